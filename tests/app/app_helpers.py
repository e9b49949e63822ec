"""Helpers for the app tests: simulated drops, viewport pixels, quick settings."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator

import numpy as np
from PySide6.QtCore import QMimeData, QPointF, Qt, QUrl
from PySide6.QtGui import QDragEnterEvent, QDropEvent
from PySide6.QtWidgets import QApplication

#: Small, quick fits: the tests check behaviour, not accuracy.
#: a long live run on a fixed 8 x 8 grid: the least-squares core's passes, then the gradient fit
QUICK = {"control_points_u": 8, "control_points_v": 8, "iterations": 100000, "solver": "gradient",
         "max_control_points": 0}


@contextlib.contextmanager
def app_process_env() -> Iterator[dict[str, str]]:
    """The environment of a child ``python -m app``: its own empty settings folder
    (``XDG_CONFIG_HOME``, removed afterwards), so that children of tests running side by side
    (pytest-xdist workers) never share a settings file or see each other's recent files."""
    with tempfile.TemporaryDirectory(prefix="nurbs-studio-config-") as config:
        yield dict(os.environ, QT_API="pyside6", XDG_CONFIG_HOME=config)


def sin_cos_cloud(count: int = 1500, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-3.0, 3.0, size=(count, 2))
    return np.column_stack([xy, np.sin(xy[:, 0]) * np.cos(xy[:, 1])])


def drop_files(widget, paths):
    """Simulate dropping files on the widget (drag-enter then drop, as Qt delivers them)."""
    mime = QMimeData()
    mime.setUrls([QUrl.fromLocalFile(str(p)) for p in paths])
    position = QPointF(widget.width() / 2, widget.height() / 2)
    buttons, modifiers = Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier
    enter = QDragEnterEvent(position, Qt.DropAction.CopyAction, mime, buttons, modifiers)
    QApplication.sendEvent(widget, enter)
    assert enter.isAccepted(), "the window refused the drag"
    drop = QDropEvent(position, Qt.DropAction.CopyAction, mime, buttons, modifiers)
    QApplication.sendEvent(widget, drop)
    return drop.isAccepted()


def open_by_drop(qtbot, window, paths, expect: bool = True, timeout: int = 20000):
    with qtbot.waitSignal(window.files_loaded, timeout=timeout) as blocker:
        drop_files(window, paths)
    assert blocker.args == [expect], window.last_error
    return blocker


def viewport_image(window) -> np.ndarray:
    """The viewport's rendered pixels (H, W, 3) uint8, straight from the render window."""
    window.scene.render_now()
    return np.asarray(window.scene.plotter.screenshot(return_img=True))[..., :3]


def export_report(qtbot, window, monkeypatch, path) -> str:
    """File > deviation report saved to ``path`` (the save dialog answered): the HTML's text;
    the export must succeed."""
    from PySide6.QtWidgets import QFileDialog

    monkeypatch.setattr(QFileDialog, "getSaveFileName",
                        staticmethod(lambda *a, **k: (str(path), "HTML report (*.html)")))
    with qtbot.waitSignal(window.export_finished, timeout=60000) as blocker:
        window.report_action.trigger()
    assert blocker.args == [str(path), True], window.last_error
    return path.read_text()


def solid_route_off(window) -> None:
    """Turn "Solid from analytic faces" off (an undoable settings edit): a closed cloud one
    patch refuses then goes on as a network of patches, as before the part route (with it on
    auto, ``choose_route`` makes a solid of a part-like scan: a sphere is one)."""
    combo = window.solid_panel.setting
    combo.setCurrentIndex(combo.findData("off"))
    assert window.document.settings.solid == "off"


def save_session(qtbot, window, path, expect: bool = True, timeout: int = 60000) -> None:
    """Save the session to ``path`` (a job) and wait for its end; it must end as ``expect``."""
    with qtbot.waitSignal(window.session_saved, timeout=timeout) as blocker:
        assert window.save_session(str(path))
    assert blocker.args == [str(path), expect], window.last_error


def open_session(qtbot, window, path, expect: bool = True, timeout: int = 60000) -> None:
    """Open the session ``path`` (a load job) and wait for its end; it must end as ``expect``."""
    with qtbot.waitSignal(window.files_loaded, timeout=timeout) as blocker:
        assert window.open_session(str(path))
    assert blocker.args == [expect], window.last_error
