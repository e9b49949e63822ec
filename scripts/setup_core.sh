#!/usr/bin/env bash
# The engine-only environment: a second virtual environment, .venv-core, with the CPU build of
# torch and the project WITHOUT the app extra (no PySide6, VTK, pyvista), for running tests/core
# the way a headless user of nurbs_core installs it. Safe to run again: it only installs what is
# missing. Fails if a GUI package is importable there.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON="${PYTHON:-python3}"
if [ ! -x .venv-core/bin/python ]; then
  echo "[setup-core] creating .venv-core with $($PYTHON --version)"
  "$PYTHON" -m venv .venv-core
fi
# torch first and pinned: the CPU build (a bare 'torch' would pull a multi-GB CUDA build).
if ! .venv-core/bin/python -c "import torch" >/dev/null 2>&1; then
  echo "[setup-core] installing torch (CPU build)"
  .venv-core/bin/python -m pip install -q --upgrade pip
  .venv-core/bin/python -m pip install -q "torch==2.13.0"
fi
echo "[setup-core] installing nurbs-studio with extras [cad,e57,test-core] (no app extra)"
.venv-core/bin/python -m pip install -q -e ".[cad,e57,test-core]" "torch==2.13.0"
# the point of this environment: the GUI stack must be absent
.venv-core/bin/python - <<'PY'
import importlib.util
import sys

present = [name for name in ("PySide6", "shiboken6", "vtk", "vtkmodules", "pyvista", "pyvistaqt",
                             "superqt", "pyqtgraph", "pytestqt")
           if importlib.util.find_spec(name) is not None]
if present:
    sys.exit(f"[setup-core] .venv-core must not contain the GUI stack, found: {', '.join(present)}")
PY
echo "[setup-core] ready: .venv-core"
