"""The main window: menus, docks, status bar and the wiring between them (no fitting logic).

Layout: the VTK viewport in the centre; on the left the document tree; on the right the fit
settings, knots, offsets and the patch network settings; at the bottom the loss plot, the fit's
quality (and the patch network's) and the log. Long work (reading files, tessellating patches,
offsets, export) runs in :class:`JobRunner` threads, the fits in their controllers' worker
threads; this module only touches widgets, on the GUI thread. The toolbar's Mode box picks which
fit Start, Pause, Stop, Reset and Export work on: one patch or a patch network.

Reading files can take long (a huge scan) or never end (a reader stuck on a hostile file): a load
runs in an abandonable thread, the status bar shows a Cancel button while it runs (Esc too), and
closing the window abandons it instead of waiting. Files the app writes itself (sessions,
screenshots) are written atomically: a failed write leaves the previous file as it was.
"""

from __future__ import annotations

import gc
import importlib.util
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSettings, Qt, QTimer, Signal, Slot
from PySide6.QtGui import QAction, QIcon, QKeySequence
from PySide6.QtWidgets import (
    QAbstractButton,
    QApplication,
    QDockWidget,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QMainWindow,
    QMessageBox,
    QProgressBar,
    QScrollArea,
    QStyle,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from app import loading
from app.controller import FitController
from app.demo import ICON_FILE, demo_path
from app.errors import describe, is_expected, log_failure, one_line
from app.offsets import OffsetController
from app.panels.document_tree import DocumentTree
from app.panels.fit_panel import POLICY_TEXT, FitSettingsPanel
from app.panels.knot_panel import KnotPanel
from app.panels.log_panel import LogPanel
from app.panels.loss_plot import LossPlot
from app.panels.network_quality_panel import NetworkQualityPanel
from app.panels.offset_panel import OffsetPanel
from app.panels.patches_panel import ModeSelector, PatchesPanel
from app.panels.quality_panel import QualityPanel
from app.patch_controller import PatchController
from app.patch_view import PatchView
from app.state import FIT_MODES, Document, Settings, control_grid_for
from app.viewport.scene import SceneView
from app.workers.fit_worker import DisplaySnapshot, deviation_stats
from app.workers.jobs import JobRunner

log = logging.getLogger("app")

MAX_RECENT = 10
OFFSET_FIELDS = {"offset_distance", "constrain_shared_edges", "show_offsets"}
SESSION_FILTER = "NURBS Studio session (*.json)"
FIT_AS_PATCHES = "Fit as patches"
#: a load that ends sooner shows no progress indicator (no flicker for small files)
LOAD_INDICATOR_DELAY_MS = 300


@dataclass
class _Load:
    """The load in progress: its detached job and what it reads."""

    job_id: int
    paths: list[str]
    started: float


def freeze_long_lived_objects():
    """Move everything alive now (torch, VTK, Qt and their modules) out of the garbage collector's
    reach.

    A full (generation 2) collection otherwise walks all of those objects with the GIL held: we
    measured 270 ms in the GUI thread and 690 ms in the fit worker, each a frozen event loop. Only
    objects created later are scanned after ``gc.freeze()``.
    """
    gc.collect()
    gc.freeze()


def _names(names: list[str], shown: int = 3) -> str:
    """"a, b, c and 24 more": file lists short enough for a status bar."""
    if len(names) <= shown:
        return ", ".join(names)
    return f"{', '.join(names[:shown])} and {len(names) - shown} more"


def _format_seconds(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "-"
    seconds = max(0.0, seconds)
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def _set_checked_quietly(action, checked: bool):
    """Tick or untick a checkable action without re-emitting its toggled signal."""
    if action.isChecked() != checked:
        action.blockSignals(True)
        action.setChecked(checked)
        action.blockSignals(False)


class MainWindow(QMainWindow):
    """NURBS Studio's window. Public methods are what menus, drops, scripts and tests call."""

    files_loaded = Signal(bool)  # True: the document now holds the files; False: load failed
    export_finished = Signal(str, bool)  # path, success
    offsets_updated = Signal(bool)
    error_shown = Signal(str)

    def __init__(self, settings_store: QSettings | None = None):
        super().__init__()
        self.setWindowTitle("NURBS Studio")
        if ICON_FILE.is_file():
            self.setWindowIcon(QIcon(str(ICON_FILE)))
        self.resize(1400, 900)
        self.setAcceptDrops(True)
        self._store = settings_store or QSettings("NURBS Studio", "nurbs-studio")
        self._store.setAtomicSyncRequired(True)  # Qt writes it through QSaveFile: all or nothing
        self._is_shut_down = False
        self._message_box: QMessageBox | None = None
        self.fit_as_patches_button: QAbstractButton | None = None
        self.last_error = ""
        self.load_message = ""  # one line: how the latest load ended (opened, failed, cancelled)
        self._load: _Load | None = None
        self._quality_run = 0  # the run whose snapshots the quality readout follows

        self.document = Document(self)
        self.controller = FitController(self.document, self)
        self.patch_controller = PatchController(self.document, self)
        self.jobs = JobRunner(self)
        self.scene = SceneView(self)
        self.setCentralWidget(self._native_container(self.scene.widget))

        self._build_docks()
        self.offsets = OffsetController(self.document, self.jobs, self.scene, self.offset_panel,
                                        self.report, self)
        self.offsets.offsets_updated.connect(self.offsets_updated)
        self.offsets.offsets_updated.connect(lambda _ok: self._rebuild_tree())
        self._build_actions()
        self._build_menus()
        self._build_status_bar()
        self.patch_view = PatchView(self.patch_controller, self.scene, self.network_quality_panel,
                                    self.status_labels, self.report, self)
        self._connect()
        self._show_settings(self.document.settings)
        self._on_state_changed("idle")
        app = QApplication.instance()
        if app is not None:
            app.aboutToQuit.connect(self.shutdown)
        freeze_long_lived_objects()

    # --- construction ----------------------------------------------------------------------------
    @staticmethod
    def _native_container(viewport: QWidget) -> QWidget:
        """Host the OpenGL viewport in its own native child window.

        A QOpenGLWidget makes Qt composite its whole top-level window through OpenGL on every
        repaint of any widget (a status label, the loss plot). With software OpenGL that cost
        ~100 ms per repaint of a large window and stalled the event loop during fits; in a native
        child window only the viewport's own area is composited.
        """
        container = QWidget()
        container.setAttribute(Qt.WidgetAttribute.WA_DontCreateNativeAncestors)
        container.setAttribute(Qt.WidgetAttribute.WA_NativeWindow)
        layout = QVBoxLayout(container)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(viewport)
        return container

    def _dock(self, title: str, widget: QWidget, area, name: str, scroll: bool = False):
        dock = QDockWidget(title, self)
        dock.setObjectName(name)
        if scroll:
            area_widget = QScrollArea()
            area_widget.setWidgetResizable(True)
            area_widget.setWidget(widget)
            widget = area_widget
        dock.setWidget(widget)
        self.addDockWidget(area, dock)
        return dock

    def _build_docks(self):
        right = Qt.DockWidgetArea.RightDockWidgetArea
        bottom = Qt.DockWidgetArea.BottomDockWidgetArea
        self.tree = DocumentTree(self.set_layer_visible, self.set_target_visible)
        self.fit_panel = FitSettingsPanel(self.document.edit_settings)
        self.knot_panel = KnotPanel(self.document.edit_settings, self.report)
        self.offset_panel = OffsetPanel(self.document.edit_settings)
        self.patches_panel = PatchesPanel(self.document.edit_patches)
        self.network_quality_panel = NetworkQualityPanel()
        self.loss_plot = LossPlot()
        self.quality_panel = QualityPanel()
        self.log_panel = LogPanel()
        logging.getLogger().addHandler(self.log_panel.handler)
        if logging.getLogger().level > logging.INFO or logging.getLogger().level == 0:
            logging.getLogger().setLevel(logging.INFO)
        self.tree_dock = self._dock("Document", self.tree, Qt.DockWidgetArea.LeftDockWidgetArea,
                                    "document_dock")
        self.fit_dock = self._dock("Fit settings", self.fit_panel, right, "fit_dock", True)
        self.knot_dock = self._dock("Knots", self.knot_panel, right, "knot_dock")
        self.offset_dock = self._dock("Offsets", self.offset_panel, right, "offset_dock", True)
        self.tabifyDockWidget(self.fit_dock, self.knot_dock)
        self.patches_dock = self._dock("Patches", self.patches_panel, right, "patches_dock", True)
        self.tabifyDockWidget(self.knot_dock, self.offset_dock)
        self.tabifyDockWidget(self.offset_dock, self.patches_dock)
        self.fit_dock.raise_()
        self.loss_dock = self._dock("Loss", self.loss_plot, bottom, "loss_dock")
        self.quality_dock = self._dock("Quality", self.quality_panel, bottom, "quality_dock", True)
        self.network_quality_dock = self._dock("Patch quality", self.network_quality_panel,
                                               bottom, "network_quality_dock", True)
        self.log_dock = self._dock("Log", self.log_panel, bottom, "log_dock")
        self.splitDockWidget(self.loss_dock, self.quality_dock, Qt.Orientation.Horizontal)
        self.splitDockWidget(self.quality_dock, self.log_dock, Qt.Orientation.Horizontal)
        self.tabifyDockWidget(self.quality_dock, self.network_quality_dock)
        self.quality_dock.raise_()
        self.resizeDocks([self.tree_dock, self.fit_dock], [240, 330], Qt.Orientation.Horizontal)
        self.resizeDocks([self.loss_dock, self.quality_dock, self.log_dock], [420, 560, 420],
                         Qt.Orientation.Horizontal)
        self.resizeDocks([self.loss_dock], [210], Qt.Orientation.Vertical)

    def _action(self, text: str, slot, shortcut=None, icon=None, checkable=False, checked=False):
        action = QAction(text, self)
        if shortcut:
            action.setShortcut(QKeySequence(shortcut))
        if icon is not None:
            action.setIcon(self.style().standardIcon(icon))
        if checkable:
            action.setCheckable(True)
            action.setChecked(checked)
            action.toggled.connect(slot)
        else:
            action.triggered.connect(slot)
        return action

    def _build_actions(self):
        pixmap = QStyle.StandardPixmap
        self.open_action = self._action("&Open...", self._open_dialog,
                                        QKeySequence.StandardKey.Open, pixmap.SP_DialogOpenButton)
        self.demo_action = self._action("Open &Demo", self.open_demo)
        self.cancel_load_action = self._action("&Cancel Loading", self.cancel_load,
                                               QKeySequence(Qt.Key.Key_Escape),
                                               pixmap.SP_DialogCancelButton)
        self.cancel_load_action.setToolTip("Stop reading the files (Esc); the document stays "
                                           "as it was")
        self.cancel_load_action.setEnabled(False)
        self.open_session_action = self._action("Open &Session...", self._open_session_dialog)
        self.save_session_action = self._action("&Save Session...", self._save_session_dialog,
                                                QKeySequence.StandardKey.Save,
                                                pixmap.SP_DialogSaveButton)
        self.screenshot_action = self._action("Save Screens&hot...", self._screenshot_dialog)
        self.quit_action = self._action("&Quit", self.close, QKeySequence.StandardKey.Quit)
        self.start_action = self._action("&Start", self.start_fit, "F5", pixmap.SP_MediaPlay)
        self.pause_action = self._action("&Pause", lambda *_: self.active_controller().pause(), "F6",
                                         pixmap.SP_MediaPause)
        self.resume_action = self._action("Res&ume", lambda *_: self.active_controller().resume(),
                                          "F7", pixmap.SP_MediaSeekForward)
        self.stop_action = self._action("S&top", lambda *_: self.active_controller().stop(),
                                        "Shift+F5", pixmap.SP_MediaStop)
        self.reset_action = self._action("&Reset", self.reset_fit, "Ctrl+R",
                                         pixmap.SP_BrowserReload)
        for action, tip in ((self.start_action, "Start fitting (continues from the current shape)"),
                            (self.reset_action, "Stop and discard the fitted shape")):
            action.setToolTip(tip)
        self.undo_action = self.document.undo_stack.createUndoAction(self, "&Undo")
        self.undo_action.setShortcut(QKeySequence.StandardKey.Undo)
        self.redo_action = self.document.undo_stack.createRedoAction(self, "&Redo")
        self.redo_action.setShortcut(QKeySequence.StandardKey.Redo)
        self.layer_actions = {}
        for layer, text, on in (("cloud", "Point Cloud", True), ("surface", "Fitted Surface", True),
                                ("curve", "Fitted Curve", True),
                                ("control_net", "Control Net", False),
                                ("knot_lines", "Knot Lines", True), ("patches", "Patches", True),
                                ("offsets", "Offsets", True), ("network", "Patch Network", True),
                                ("layout", "Patch Layout", True)):
            self.layer_actions[layer] = self._action(
                text, lambda checked, layer=layer: self.set_layer_visible(layer, checked),
                checkable=True, checked=on)
        self.layer_actions["control_net"].setShortcut(QKeySequence("N"))
        self.deviation_action = self._action("&Deviation Map", self.set_deviation_visible, "D",
                                             checkable=True, checked=True)
        self.quality_action = self._action("&Quality Map", self.set_quality_visible, "Q",
                                           checkable=True, checked=False)
        self.quality_action.setToolTip("Paint the fitted surface where it is flipped, overlaps "
                                       "itself or hangs far from the cloud")
        self.seam_action = self._action("Seam &Angle Map", self.set_seam_visible, "A",
                                        checkable=True, checked=False)
        self.seam_action.setToolTip("Colour the patch network by the angle between neighbouring "
                                    "patches along their seams")
        self.camera_action = self._action("&Fit View", self.scene.reset_camera, "F")

    def _build_menus(self):
        bar = self.menuBar()
        file_menu = bar.addMenu("&File")
        file_menu.addAction(self.open_action)
        self.recent_menu = file_menu.addMenu("Open &Recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent_menu)
        file_menu.addAction(self.demo_action)
        file_menu.addAction(self.cancel_load_action)
        file_menu.addSeparator()
        file_menu.addAction(self.open_session_action)
        file_menu.addAction(self.save_session_action)
        file_menu.addSeparator()
        self.export_menu = file_menu.addMenu("&Export")
        self.export_actions = {}
        has_ocp = importlib.util.find_spec("OCP") is not None
        for label, suffix, needs_ocp in loading.EXPORT_FORMATS:
            if needs_ocp and not has_ocp:
                text = f"{label} ({suffix}): needs {loading.CAD_INSTALL_HINT}"
                action = self._action(text, lambda _=False, label=label: self.report(
                    f"{label} export needs the optional CAD extra. Install it with: "
                    f"{loading.CAD_INSTALL_HINT}", error=True))
            else:
                action = self._action(f"{label} ({suffix})...",
                                      lambda _=False, label=label, suffix=suffix:
                                      self._export_dialog(label, suffix))
            self.export_menu.addAction(action)
            self.export_actions[suffix] = action
        file_menu.addAction(self.screenshot_action)
        file_menu.addSeparator()
        file_menu.addAction(self.quit_action)

        edit_menu = bar.addMenu("&Edit")
        edit_menu.addAction(self.undo_action)
        edit_menu.addAction(self.redo_action)

        fit_menu = bar.addMenu("F&it")
        for action in (self.start_action, self.pause_action, self.resume_action,
                       self.stop_action, self.reset_action):
            fit_menu.addAction(action)
        fit_menu.addSeparator()
        policy = fit_menu.addAction(POLICY_TEXT)
        policy.setEnabled(False)

        view_menu = bar.addMenu("&View")
        for action in self.layer_actions.values():
            view_menu.addAction(action)
        view_menu.addAction(self.deviation_action)
        view_menu.addAction(self.quality_action)
        view_menu.addAction(self.seam_action)
        view_menu.addSeparator()
        view_menu.addAction(self.camera_action)
        view_menu.addSeparator()
        for dock in (self.tree_dock, self.fit_dock, self.knot_dock, self.offset_dock,
                     self.patches_dock, self.loss_dock, self.quality_dock,
                     self.network_quality_dock, self.log_dock):
            view_menu.addAction(dock.toggleViewAction())

        toolbar = self.addToolBar("Fit")
        toolbar.setObjectName("fit_toolbar")
        toolbar.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextBesideIcon)
        toolbar.addAction(self.open_action)
        toolbar.addSeparator()
        toolbar.addWidget(QLabel(" Mode "))
        self.mode_selector = ModeSelector(self.document.edit_settings)
        toolbar.addWidget(self.mode_selector)
        for action in (self.start_action, self.pause_action, self.resume_action,
                       self.stop_action, self.reset_action):
            toolbar.addAction(action)
        toolbar.addSeparator()
        toolbar.addAction(self.undo_action)
        toolbar.addAction(self.redo_action)

    def _build_status_bar(self):
        # while a load runs: a busy bar and Cancel, left of the fit's labels (hidden otherwise)
        self.load_indicator = QWidget()
        layout = QHBoxLayout(self.load_indicator)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(4)
        self.load_progress = QProgressBar()  # busy (range 0-0) only while shown: no animation
        self.load_progress.setTextVisible(False)
        self.load_progress.setFixedSize(90, 12)
        self.load_cancel_button = QToolButton()
        self.load_cancel_button.setDefaultAction(self.cancel_load_action)  # shows its text
        self.load_cancel_button.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextBesideIcon)
        self.load_cancel_button.setAutoRaise(True)
        layout.addWidget(self.load_progress)
        layout.addWidget(self.load_cancel_button)
        self.statusBar().addPermanentWidget(self.load_indicator)
        self.load_indicator.hide()
        self._load_indicator_timer = QTimer(self)
        self._load_indicator_timer.setSingleShot(True)
        self._load_indicator_timer.setInterval(LOAD_INDICATOR_DELAY_MS)
        self._load_indicator_timer.timeout.connect(self._show_load_indicator)
        self.status_labels = {}
        for name, width in (("state", 90), ("iteration", 130), ("loss", 140), ("rate", 100),
                            ("remaining", 120)):
            label = QLabel("-")
            label.setMinimumWidth(width)
            self.statusBar().addPermanentWidget(label)
            self.status_labels[name] = label

    def _connect(self):
        doc, ctl = self.document, self.controller
        doc.settings_changed.connect(self._on_settings_changed)
        doc.content_changed.connect(self._on_content_changed)
        doc.fitted_changed.connect(self._on_fitted_changed)
        ctl.state_changed.connect(self._on_state_changed)
        self.patch_controller.state_changed.connect(self._on_state_changed)
        self.patch_controller.snapshot_shown.connect(self._on_patch_snapshot)
        self.patch_controller.losses_received.connect(self.loss_plot.append)
        ctl.snapshot_shown.connect(self._on_snapshot_shown)
        ctl.losses_received.connect(self.loss_plot.append)
        ctl.progress_changed.connect(self._on_progress)
        ctl.fit_finished.connect(self._on_fit_finished)
        ctl.fit_failed.connect(lambda message: self.report(
            message, error=True, offer_patches=self.controller.failure_needs_patches))

    # --- messages --------------------------------------------------------------------------------
    def report(self, message: str, error: bool = False, offer_patches: bool = False,
               exc: BaseException | None = None):
        """Tell the user: log dock, status bar, and a (non-blocking) dialog for errors.

        The log and the status bar get the message as one line; the dialog shows it as written.
        exc: the exception behind an error; its traceback is logged only when it is a bug (not
        bad input: :func:`app.errors.is_expected`). offer_patches: the dialog gets a "Fit as
        patches" button (switch to Patches mode and start the patch fit)."""
        line = one_line(message)
        if error:
            log_failure(log, line, exc, user_report=True)
        else:
            log.info("%s", line)
        self.statusBar().showMessage(line, 8000)
        if error:
            self.last_error = message
            if self._message_box is not None:
                self._message_box.reject()  # close() is ignored by a box without an Escape button
            self._message_box = QMessageBox(QMessageBox.Icon.Warning, "NURBS Studio", message,
                                            QMessageBox.StandardButton.Ok, self)
            self.fit_as_patches_button = None
            if offer_patches:
                self.fit_as_patches_button = self._message_box.addButton(
                    FIT_AS_PATCHES, QMessageBox.ButtonRole.AcceptRole)
                self._message_box.setDefaultButton(self.fit_as_patches_button)
                self._message_box.buttonClicked.connect(self._on_message_button)
            self._message_box.open()
            self.error_shown.emit(message)

    @Slot(QAbstractButton)
    def _on_message_button(self, button: QAbstractButton):
        if button is not None and button is self.fit_as_patches_button:
            self.fit_as_patches()

    # --- loading ---------------------------------------------------------------------------------
    def open_files(self, paths: list[str]) -> bool:
        """Read the files in an abandonable worker thread; the document changes only if every
        file reads. A load still running is cancelled (the newest request wins). Every load
        started here ends with one ``files_loaded``: True when applied, False when it failed or
        was cancelled (none when the window closes first)."""
        paths = [str(p) for p in paths]
        if not paths or self._is_shut_down:
            return False
        if self._load is not None:
            self.cancel_load()
        job_id = self.jobs.submit_detached(
            "load", lambda cancel: loading.load_files(paths, cancel),
            lambda loaded: self._on_load_done(paths, loaded),
            lambda exc: self._on_load_error(paths, exc))
        if not job_id:
            return False
        self._load = _Load(job_id, paths, time.monotonic())
        self.cancel_load_action.setEnabled(True)
        self._load_indicator_timer.start()
        self.statusBar().showMessage(f"Reading {_names([Path(p).name for p in paths])}... "
                                     "(Esc cancels)")
        return True

    def is_loading(self) -> bool:
        return self._load is not None

    def cancel_load(self, *_args, quiet: bool = False) -> bool:
        """Abandon the load in progress (Cancel, Esc): returns at once and loads nothing; the
        reader thread is left to end on its own and its result is dropped. quiet: no report
        (the caller tells the user). False when no load runs."""
        load = self._load
        if load is None:
            return False
        self.jobs.cancel(load.job_id)
        self._load_ended()
        seconds = time.monotonic() - load.started
        after = f" after {_format_seconds(seconds)}" if seconds >= 1.0 else ""
        self.load_message = (f"Cancelled opening {_names([Path(p).name for p in load.paths])}"
                             f"{after}; the document was left unchanged.")
        if not quiet:
            self.report(self.load_message)
        self.files_loaded.emit(False)
        return True

    def _load_ended(self):
        """No load runs any more: its indicator and Cancel go."""
        self._load = None
        self._load_indicator_timer.stop()
        self.load_indicator.hide()
        self.load_progress.setRange(0, 1)  # stops the style's busy animation
        self.cancel_load_action.setEnabled(False)

    def _on_load_done(self, paths: list[str], loaded: loading.LoadedFiles):
        self._load_ended()
        self._apply_loaded(paths, loaded)

    def _on_load_error(self, paths: list[str], exc: BaseException):
        self._load_ended()
        self._load_failed(paths, exc)

    @Slot()
    def _show_load_indicator(self):
        if self._load is not None and not self._is_shut_down:
            self.load_progress.setRange(0, 0)  # busy: readers do not report progress
            self.load_indicator.show()

    def open_demo(self) -> bool:
        return self.open_files([str(demo_path())])

    def _apply_loaded(self, paths: list[str], loaded: loading.LoadedFiles):
        self.controller.reset()
        self._reset_patches()
        self.loss_plot.clear()
        for label in self.status_labels.values():
            label.setText("-")
        self.status_labels["state"].setText("Idle")
        self.document.replace_content(loaded.targets, loaded.patches, loaded.patch_names)
        points = self.document.target_points()
        if points is not None and np.ptp(points[:, 2]) == 0 and self.document.settings.fit.kind != (
                "curve"):
            self.document.edit_settings("Kind (planar cloud)", kind="curve")
            self.report("The cloud is planar: switched to curve fitting (2D).")
        grid = None if points is None else control_grid_for(len(points), self.document.settings.fit)
        if grid is not None:
            self.document.edit_settings("Control grid (small cloud)", control_points_u=grid[0],
                                        control_points_v=grid[1])
            self.report(f"{len(points)} points are few for the control grid: reduced it to "
                        f"{grid[0]} x {grid[1]} (Edit > Undo to keep the larger grid).")
        for path in paths:
            self._add_recent(path)
        counts = [f"{len(t.points)} points in {t.name}" for t in loaded.targets]
        if loaded.patch_names:
            sources = sorted({Path(p).name for p in paths} - {t.name for t in loaded.targets})
            counts.append(f"{len(loaded.patch_names)} NURBS shape(s) from {_names(sources)}")
        self.load_message = f"Opened {'; '.join(counts)}"
        self.report(self.load_message)
        self.setWindowTitle(f"NURBS Studio - {_names([Path(p).name for p in paths])}")
        self.files_loaded.emit(True)

    def _load_failed(self, paths: list[str], exc: BaseException):
        """One line naming the file and the problem (the log gets a traceback only for a bug),
        then what it means for the document."""
        path = getattr(exc, "load_path", None) or (paths[0] if len(paths) == 1 else None)
        problem = describe(exc)
        if path is None:
            headline = f"Could not open {_names([Path(p).name for p in paths])}: {problem}"
        elif Path(path).name in problem:
            headline = f"Could not open {problem}"  # the reader's message names the file
        else:
            headline = f"Could not open {path}: {problem}"
        if not is_expected(exc):
            headline += " (an unexpected error: the log has the details)"
        self.load_message = message = headline
        hint = getattr(exc, "install", None)
        if hint and hint not in message:
            message += f"\nInstall the missing package with: {hint}"
        self.report(message + "\nThe document was left unchanged.", error=True, exc=exc)
        self.files_loaded.emit(False)

    def _open_dialog(self):
        suffixes = " ".join(f"*{s}" for s in loading.open_suffixes())
        paths, _ = QFileDialog.getOpenFileNames(
            self, "Open point clouds or NURBS files", self._last_directory(),
            f"Supported files ({suffixes});;All files (*)")
        if paths:
            self.open_files(paths)

    def _last_directory(self) -> str:
        recent = self.recent_files()
        return str(Path(recent[0]).parent) if recent else str(Path.home())

    def recent_files(self) -> list[str]:
        value = self._store.value("recent_files", [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def _add_recent(self, path: str):
        if Path(path).resolve() == Path(demo_path()).resolve():
            return
        recent = [p for p in self.recent_files() if p != path]
        self._store.setValue("recent_files", [path, *recent][:MAX_RECENT])

    def _fill_recent_menu(self):
        self.recent_menu.clear()
        recent = self.recent_files()
        if not recent:
            self.recent_menu.addAction("(none)").setEnabled(False)
        for path in recent:
            action = self.recent_menu.addAction(path)
            action.triggered.connect(lambda _=False, path=path: self.open_files([path]))

    def dragEnterEvent(self, event):  # noqa: N802 - Qt override
        if event.mimeData().hasUrls() and all(u.isLocalFile() for u in event.mimeData().urls()):
            event.acceptProposedAction()
        else:
            event.ignore()

    def dropEvent(self, event):  # noqa: N802 - Qt override
        paths = [u.toLocalFile() for u in event.mimeData().urls() if u.isLocalFile()]
        if paths:
            event.acceptProposedAction()
            self.open_files(paths)

    # --- document -> view ------------------------------------------------------------------------
    @Slot()
    def _on_content_changed(self):
        points = self.document.target_points()
        self.scene.set_cloud(points)
        self.knot_panel.set_points(points)
        patches = list(self.document.patches)
        self.scene.set_group("patches", [])
        self.scene.set_group("offsets", [])
        self.scene.set_note("")
        if patches:
            self.jobs.submit("tessellate", lambda: loading.tessellate(patches),
                             self._show_patches,
                             lambda exc: self.report(
                                 f"Cannot display the patches: {describe(exc)}", True, exc=exc))
            self.offsets.request()
        self.scene.reset_camera()
        self._rebuild_tree()

    def _show_patches(self, displays):
        self.scene.set_group("patches", displays)
        self.scene.reset_camera()

    @Slot()
    def _on_fitted_changed(self):
        """The fitted shape was replaced outside a live run (reset, session): redisplay it."""
        fitted = self.document.fitted
        if fitted is None:
            self.scene.show_fit(None)
            self.scene.set_deviation(None)
            self.quality_panel.clear()
        else:
            points = self.document.target_points()
            self.quality_panel.clear("Measuring the fitted shape...")
            self.jobs.submit("fitted", lambda: loading.fitted_display(fitted, points),
                             lambda result: self._show_fitted_display(fitted, result),
                             lambda exc: self.report(
                                 f"Cannot display the fit: {describe(exc)}", True, exc=exc))
        self._rebuild_tree()
        self.knot_panel.show_state(self.document.settings.fit, fitted)

    def _show_fitted_display(self, fitted: dict, result: loading.FittedDisplay):
        if self.document.fitted is not fitted:
            return  # replaced meanwhile (a new fit, another session)
        self.scene.show_fit(result.display)
        if result.deviation is not None:
            stats = deviation_stats(result.deviation)
            self.scene.set_deviation(result.deviation, stats)
            self.quality_panel.show_deviation(stats)
        self.scene.set_quality(result.quality_cells, result.statistics)
        self.quality_panel.show_result("measured", "the fitted shape against the cloud",
                                       result.statistics, self.document.settings.fit.tolerance is None,
                                       result.display.kind)
        self._rebuild_tree()

    def _rebuild_tree(self):
        self.tree.rebuild(self.document, self.scene.is_visible, self.deviation_action.isChecked(),
                          self.quality_action.isChecked(), self.seam_action.isChecked())

    def set_layer_visible(self, layer: str, visible: bool):
        if layer == "deviation":
            self.set_deviation_visible(visible)
            return
        if layer == "quality":
            self.set_quality_visible(visible)
            return
        if layer == "seam":
            self.set_seam_visible(visible)
            return
        self.scene.set_visible(layer, visible)
        action = self.layer_actions.get(layer)
        if action is not None:
            _set_checked_quietly(action, visible)
        self._rebuild_tree()

    def set_deviation_visible(self, visible: bool):
        self.scene.set_deviation_visible(visible)
        _set_checked_quietly(self.deviation_action, visible)
        self._rebuild_tree()

    def set_quality_visible(self, visible: bool):
        """Paint the fitted surface by its quality map (flipped, overlapping, far)."""
        self.scene.set_quality_visible(visible)
        _set_checked_quietly(self.quality_action, visible)
        self._rebuild_tree()

    def set_seam_visible(self, visible: bool):
        """Colour the patch network by its seam angles (with a colour bar in degrees)."""
        self.scene.network.set_seam_visible(visible)
        _set_checked_quietly(self.seam_action, visible)
        self._rebuild_tree()

    def set_target_visible(self, index: int, visible: bool):
        """Hide a cloud from the view and from the fit target (applies to the next run)."""
        self.document.targets[index].visible = visible
        self.scene.set_cloud(self.document.target_points())
        self.knot_panel.set_points(self.document.target_points())
        role = "part of" if visible else "left out of"
        self.report(f"{self.document.targets[index].name} is {role} the fit target from the "
                    "next Start.")

    # --- settings --------------------------------------------------------------------------------
    def _show_settings(self, settings: Settings):
        self.mode_selector.show_settings(settings)
        self.patches_panel.show_settings(settings.patches)
        self.scene.set_mode(settings.fit_mode)
        self.fit_panel.show_settings(settings.fit)
        self.offset_panel.show_settings(settings)
        self.knot_panel.show_state(settings.fit, self.document.fitted)

    @Slot(object, object)
    def _on_settings_changed(self, old: Settings, new: Settings):
        self._show_settings(new)
        if old.fit_mode != new.fit_mode:
            self._mode_changed(new.fit_mode)
        if old.patches != new.patches:
            self._restart_or_defer(self.patch_controller)
        if old.fit != new.fit:
            self._restart_or_defer(self.controller)
        if any(getattr(old, name) != getattr(new, name) for name in OFFSET_FIELDS):
            self.offsets.request()

    def _restart_or_defer(self, controller):
        """The single-patch policy, for either fit: restart a running or paused run with the new
        settings, else apply them at the next Start (a patch fit restarts from the cloud)."""
        if controller.state in ("running", "paused", "stopping"):
            controller.schedule_restart()
            start = "the cloud" if controller is self.patch_controller else "the current shape"
            self.statusBar().showMessage(f"Settings changed: restarting the fit from {start}",
                                         4000)
        else:
            self.statusBar().showMessage("Settings changed: they apply at the next Start", 4000)

    def _mode_changed(self, mode: str):
        """The other fit stops (a run of the mode just left would draw where it is hidden)."""
        other = self.controller if mode == "patches" else self.patch_controller
        other.stop()
        if mode == "patches":
            self.patches_dock.raise_()
            self.network_quality_dock.raise_()
        else:
            self.fit_dock.raise_()
            self.quality_dock.raise_()
        self._on_state_changed()
        self._rebuild_tree()
        self.scene.reset_camera()
        what = "a patch network" if mode == "patches" else "one patch"
        self.statusBar().showMessage(f"Mode: {dict(FIT_MODES)[mode]}: Start fits {what}.", 4000)

    # --- fit -------------------------------------------------------------------------------------
    def active_controller(self) -> FitController | PatchController:
        """The controller of the fit mode on show (what Start, Pause, Stop and Reset drive)."""
        return self.patch_controller if self.document.settings.fit_mode == "patches" else (
            self.controller)

    def start_fit(self, *_args) -> bool:
        """Start the fit of the current mode (not while the other mode's fit still runs)."""
        if self.controller.is_busy() or self.patch_controller.is_busy():
            return False
        if self.active_controller() is self.patch_controller:
            self.network_quality_dock.raise_()
            self.loss_plot.clear()  # a network starts from the cloud: a new curve
            return self.patch_controller.start()
        return self.controller.start()

    def fit_as_patches(self) -> bool:
        """Switch to Patches mode (an undoable settings edit) and start the patch fit."""
        if self._message_box is not None:
            self._message_box.reject()
        self.document.edit_settings("Fit mode", fit_mode="patches")
        return self.start_fit()

    def reset_fit(self):
        if self.active_controller() is self.patch_controller:
            self._reset_patches()
            self.report("Reset: the patch network was discarded.")
            return
        self.controller.reset()
        self.loss_plot.clear()
        self.report("Reset: the next Start initializes a new shape.")

    def _reset_patches(self):
        self.patch_controller.reset()
        self.loss_plot.clear()
        self.patch_view.clear()
        self._rebuild_tree()

    @Slot(object)
    def _on_patch_snapshot(self, snapshot):
        if snapshot.network is not None and not self.tree.shows_network:
            self._rebuild_tree()  # the first network of a run: list it in the tree

    @Slot(str)
    def _on_state_changed(self, *_state):
        """Either controller's state changed: the actions follow the active one's (Start waits
        until neither runs)."""
        state = self.active_controller().state
        busy = self.controller.is_busy() or self.patch_controller.is_busy() or state != "idle"
        self.start_action.setEnabled(not busy)
        self.pause_action.setEnabled(state == "running")
        self.resume_action.setEnabled(state == "paused")
        self.stop_action.setEnabled(state in ("running", "paused"))
        self.status_labels["state"].setText(state.capitalize())
        if state == "paused":
            self.knot_panel.show_state(self.document.settings.fit, self.document.fitted)

    @Slot(object)
    def _on_snapshot_shown(self, snapshot: DisplaySnapshot):
        if not snapshot.done and snapshot.run_id != self._quality_run:
            # the first picture of a run (a refused run has none: the readout stays as it was)
            self._quality_run = snapshot.run_id
            self.quality_panel.show_running()
        self.scene.show_fit(snapshot.display)
        if snapshot.quality_cells is not None:
            self.scene.set_quality(snapshot.quality_cells, snapshot.statistics)
        if snapshot.deviation is not None:
            stats = deviation_stats(snapshot.deviation)
            self.scene.set_deviation(snapshot.deviation, stats)
            self.quality_panel.show_deviation(stats)
        if not self.tree.shows_fit:  # the first snapshot of a fit: list it in the tree
            self._rebuild_tree()

    @Slot(dict)
    def _on_progress(self, progress: dict):
        labels = self.status_labels
        # the least-squares core's passes have no count fixed in advance (iterations 0)
        labels["iteration"].setText(
            f"Iteration {progress['iteration']}/{progress['iterations']}" if progress["iterations"]
            else f"Least-squares pass {progress['iteration']}")
        loss = progress["loss"]
        labels["loss"].setText(f"Loss {loss:.4g}" if math.isfinite(loss) else "Loss -")
        labels["rate"].setText(f"{progress['rate']:.1f} it/s" if progress["rate"] else "- it/s")
        labels["remaining"].setText(f"Left {_format_seconds(progress['remaining'])}")

    @Slot(object)
    def _on_fit_finished(self, snapshot: DisplaySnapshot):
        self.loss_plot.flush()
        # already on screen: store it without the re-tessellation a notifying change triggers
        self.document.set_fitted(snapshot.geometry, notify=False)
        self._rebuild_tree()
        self.knot_panel.show_state(self.document.settings.fit, snapshot.geometry)
        text = f"Fit {snapshot.status} after {snapshot.iteration} iterations"
        if snapshot.deviation is not None:
            stats = deviation_stats(snapshot.deviation)
            text += (f"; deviation mean {stats['mean']:.4g}, RMS {stats['rms']:.4g}, "
                     f"max {stats['max']:.4g}")
        if snapshot.message:
            text += f" ({snapshot.message})"
        self.report(text)
        self.quality_panel.show_result(snapshot.status, snapshot.message, snapshot.statistics,
                                       self.document.settings.fit.tolerance is None,
                                       snapshot.display.kind)
        if self.document.settings.show_offsets and not self.document.patches:
            self.offsets.request()

    # --- export and sessions ---------------------------------------------------------------------
    def _export_dialog(self, label: str, suffix: str):
        start = str(Path(self._last_directory()) / f"nurbs_studio{suffix}")
        path, _ = QFileDialog.getSaveFileName(self, f"Export {label}", start,
                                              f"{label} (*{suffix})")
        if path:
            if not path.lower().endswith(suffix):
                path += suffix
            self.export_to(path)

    def export_to(self, path: str) -> bool:
        """Write what the mode shows: the patch network in Patches mode, else the fitted shape,
        loaded patches and offsets."""
        if self.document.settings.fit_mode == "patches":
            return self.export_network(path)
        geometries = self.document.all_geometry()
        if not geometries:
            self.report("Nothing to export yet: run a fit or open NURBS files first.", error=True)
            self.export_finished.emit(path, False)
            return False
        self.jobs.submit("export", lambda: loading.export_geometry(geometries, path),
                         lambda count: self._exported(path, count),
                         lambda exc: self._export_failed(path, exc))
        return True

    def export_network(self, path: str) -> bool:
        """Write the patch network with ``nurbs_core.io.write_network`` (format from the suffix:
        one joined B-rep in .3dm, a sewn solid in .step / .iges, our .json, a welded mesh)."""
        network = self.document.network
        if network is None:
            self.report("No patch network to export yet: Start a fit in Patches mode first.",
                        error=True)
            self.export_finished.emit(path, False)
            return False
        self.jobs.submit("export", lambda: loading.export_network(network, path),
                         lambda count: self._exported(path, count, "patch(es) of the network"),
                         lambda exc: self._export_failed(path, exc))
        return True

    def _exported(self, path: str, count: int, what: str = "shape(s)"):
        self.report(f"Exported {count} {what} to {path}")
        self.export_finished.emit(path, True)

    def _export_failed(self, path: str, exc: Exception):
        hint = getattr(exc, "install", None)
        message = f"Export to {path} failed: {describe(exc)}"
        if hint and hint not in message:
            message += f"\nInstall the missing package with: {hint}"
        if Path(path).exists():
            message += "\nThe existing file was left as it was."
        self.report(message, error=True, exc=exc)
        self.export_finished.emit(path, False)

    def _save_session_dialog(self):
        path, _ = QFileDialog.getSaveFileName(self, "Save session", self._last_directory(),
                                              SESSION_FILTER)
        if path:
            self.save_session(path)

    def _open_session_dialog(self):
        path, _ = QFileDialog.getOpenFileName(self, "Open session", self._last_directory(),
                                              SESSION_FILTER)
        if path:
            self.open_session(path)

    def save_session(self, path: str) -> bool:
        """Write the session atomically: on failure the user is told and an existing file at
        ``path`` is left byte for byte as it was."""
        try:
            self.document.save_session(path)
        except Exception as exc:  # noqa: BLE001 - told to the user (a bug also logs its trace)
            kept = "; the existing file was left as it was" if Path(path).exists() else ""
            self.report(f"Cannot save the session to {path}: {describe(exc)}{kept}",
                        error=True, exc=exc)
            return False
        self.report(f"Session saved to {path}")
        return True

    def open_session(self, path: str) -> bool:
        try:  # read and check first: a bad file must not stop or discard the current fit
            session = self.document.read_session(path)
        except Exception as exc:  # noqa: BLE001 - told to the user (a bug also logs its trace)
            self.report(f"{describe(exc)}\nThe document was left unchanged.", error=True,
                        exc=exc)
            return False
        self.controller.reset()
        self._reset_patches()
        self.loss_plot.clear()
        self.document.apply_session(session)
        self.report(f"Session opened from {path}")
        return True

    def _screenshot_dialog(self):
        path, _ = QFileDialog.getSaveFileName(self, "Save screenshot", self._last_directory(),
                                              "PNG image (*.png)")
        if path:
            self.save_screenshot(path)

    def save_screenshot(self, path: str) -> bool:
        """The whole window (viewport included) as an image (PNG; the format follows the
        suffix), written atomically: on failure an existing file is left as it was."""
        from nurbs_core.io.atomic import atomic_path

        self.loss_plot.flush()
        self.scene.render_now()
        image = self.grab()
        try:
            with atomic_path(path) as temporary:
                if not image.save(str(temporary)):
                    raise OSError("the image could not be encoded or written (is the suffix an "
                                  "image format, such as .png?)")
        except OSError as exc:
            kept = "; the existing file was left as it was" if Path(path).exists() else ""
            self.report(f"Cannot write the screenshot {path}: {describe(exc)}{kept}",
                        error=True, exc=exc)
            return False
        return True

    # --- shutdown --------------------------------------------------------------------------------
    def live_timers(self) -> int:
        return (self.controller.live_timers() + self.patch_controller.live_timers()
                + self.scene.live_timers()
                + self.loss_plot.live_timers() + int(self._load_indicator_timer.isActive()))

    def shutdown(self):
        """Stop the worker, jobs and timers and release the render window; idempotent.

        A load in progress is abandoned, not waited for (its reader may never return); the fit
        workers stop at their next iteration and are joined; short jobs (an export) complete."""
        if self._is_shut_down:
            return
        self._is_shut_down = True
        self._load_indicator_timer.stop()
        self._load = None
        self.fit_panel.cancel_pending()
        self.patches_panel.cancel_pending()
        self.controller.shutdown()
        self.patch_controller.shutdown()  # joined before the render window goes
        self.jobs.shutdown()  # abandons the load at once, then waits for the short jobs
        self.loss_plot.stop()
        self._store.sync()
        logging.getLogger().removeHandler(self.log_panel.handler)
        if self._message_box is not None:
            self._message_box.close()
        self.scene.close()

    def closeEvent(self, event):  # noqa: N802 - Qt override
        self.shutdown()
        event.accept()
