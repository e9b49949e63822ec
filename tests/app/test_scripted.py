"""Scripted runs and process exit: the real ``python -m app`` in a subprocess (same X display)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from app_helpers import app_process_env
from PySide6.QtGui import QImage

ROOT = Path(__file__).resolve().parents[2]


def _run(arguments: list[str], timeout: float = 180.0, code: str | None = None):
    command = [sys.executable, "-c", code] if code else [sys.executable, "-m", "app", *arguments]
    with app_process_env() as env:
        return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=timeout)


def test_scripted_fit_writes_a_screenshot_and_exits_zero(ply_cloud, tmp_path):
    out = tmp_path / "out.png"
    result = _run([str(ply_cloud[0]), "--fit", "--iterations", "50", "--screenshot", str(out),
                   "--quit"])
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    image = QImage(str(out))
    assert not image.isNull() and image.width() > 800 and image.height() > 500
    rgb = image.convertToFormat(QImage.Format.Format_RGB888)  # keep it alive: pixels view it
    pixels = np.frombuffer(rgb.constBits(), dtype=np.uint8, count=rgb.sizeInBytes()).reshape(
        rgb.height(), rgb.bytesPerLine())[:, : rgb.width() * 3].copy()
    assert pixels.std() > 10  # not a blank image


def test_scripted_units_are_the_documents(ply_cloud):
    result = _run([str(ply_cloud[0]), "--units", "m", "--quit"])
    assert result.returncode == 0, result.stderr
    assert "scan.ply states no units" in result.stderr and "Units: m" in result.stderr


def test_scripted_run_fails_with_status_1_on_a_bad_file(tmp_path):
    bad = tmp_path / "bad.xyz"
    bad.write_text("1 2 3\n4 five 6\n")
    result = _run([str(bad), "--fit", "--iterations", "5", "--quit"])
    assert result.returncode == 1
    assert "bad.xyz" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("moment", ["running", "paused"])
def test_closing_mid_fit_exits_zero_without_traceback(moment):
    code = f"""
import sys
import app
from PySide6.QtWidgets import QApplication
from app.main_window import MainWindow
qapp = QApplication([])
window = MainWindow()
window.show()

def loaded(ok):
    window.document.edit_settings("quick", control_points_u=8, control_points_v=8,
                                  iterations=100000)
    window.controller.start()

def shown(snapshot):
    if window.controller.snapshots_shown < 3:
        return
    if {moment!r} == "paused" and snapshot.status != "paused":
        window.controller.pause()  # the engine answers with a "paused" snapshot
        return
    window.close()  # mid-fit: the worker is still running (or paused)

window.files_loaded.connect(loaded)
window.controller.snapshot_shown.connect(shown)
window.open_demo()
sys.exit(qapp.exec())
"""
    result = _run([], code=code)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr, result.stderr


def test_no_display_gives_a_clear_message_not_a_qt_abort():
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    result = subprocess.run([sys.executable, "-m", "app", "--quit"], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert "no display found" in result.stderr and "xvfb-run" in result.stderr
