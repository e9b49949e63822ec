"""Fixtures for driving the real NURBS Studio window under Xvfb (pytest-xvfb, pytest-qt)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("QT_API", "pyside6")

from app_helpers import sin_cos_cloud  # noqa: E402
from PySide6.QtCore import QSettings  # noqa: E402


@pytest.fixture
def ply_cloud(tmp_path) -> tuple[Path, np.ndarray]:
    """A point cloud written by trimesh (a third-party PLY writer), with its points."""
    import trimesh

    points = sin_cos_cloud()
    path = tmp_path / "scan.ply"
    trimesh.PointCloud(points).export(path)
    return path, points


@pytest.fixture
def window(qtbot, tmp_path):
    """The real main window with its own settings file; closed (and checked) at the end."""
    from app.main_window import MainWindow

    store = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    win = MainWindow(settings_store=store)
    win.resize(1200, 800)
    win.show()
    qtbot.waitExposed(win)
    yield win
    win.close()
    assert not win.controller.is_busy()
    assert not win.patch_controller.is_busy()
    assert win.jobs.active_count() == 0
    # a load abandoned by Cancel or by closing may still run (a Python thread cannot be killed;
    # its result is dropped): it must be a daemon thread, which never holds up the exit
    from app.workers.jobs import abandoned_threads

    assert all(thread.daemon for thread in abandoned_threads())
