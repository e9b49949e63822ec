#!/usr/bin/env bash
# Set up NURBS Studio on a fresh Debian/Ubuntu machine: system libraries for the Qt/VTK window and
# its tests (Xvfb), a virtual environment in .venv with the CPU build of torch, and the project
# with all extras. Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

SYSTEM_PACKAGES=(
  xvfb xauth libgl1 libegl1 libglx-mesa0 libegl-mesa0 libgl1-mesa-dri libxkbcommon0
  libxkbcommon-x11-0 libx11-xcb1 libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 libxcb-image0
  libxcb-render-util0 libxcb-randr0 libxcb-shape0 libxcb-xfixes0 libxcb-xkb1 libfontconfig1
  fontconfig fonts-dejavu-core libdbus-1-3
  libusb-1.0-0
)

if command -v apt-get >/dev/null 2>&1 && [ "${NURBS_STUDIO_SKIP_APT:-0}" != 1 ]; then
  missing=()
  for pkg in "${SYSTEM_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done
  if [ "${#missing[@]}" -gt 0 ]; then
    echo "[setup] installing system packages: ${missing[*]}"
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      "${missing[@]}" >/dev/null
  fi
fi

PYTHON="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv with $($PYTHON --version)"
  "$PYTHON" -m venv .venv
fi
# torch first and pinned: the CPU build (a bare 'torch' would pull a multi-GB CUDA build).
if ! .venv/bin/python -c "import torch" >/dev/null 2>&1; then
  echo "[setup] installing torch (CPU build)"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q "torch==2.13.0"
fi
echo "[setup] installing nurbs-studio with extras [app,cad,e57,test,batch,learn]"
.venv/bin/python -m pip install -q -e ".[app,cad,e57,test,batch,learn]" "torch==2.13.0"
echo "[setup] ready: .venv"
