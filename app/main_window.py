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

What the window does when something happens lives in its policies (:mod:`app.window`): loading
files (:class:`LoadPolicy`), settings edits (:class:`SettingsPolicy`), export
(:class:`ExportPolicy`), sessions (:class:`SessionPolicy`), selecting, cropping and deleting
points (:class:`SelectionPolicy`), putting back shapes on Undo and Redo (:class:`HistoryPolicy`)
and showing a fit (:class:`FitDisplay`). This class builds
the widgets, wires the signals and keeps the public methods scripts and tests call, delegating
to those policies.
"""

from __future__ import annotations

import gc
import importlib.util
import logging

from PySide6.QtCore import QSettings, QSize, Qt, Signal, Slot
from PySide6.QtGui import QAction, QActionGroup, QGuiApplication, QIcon, QKeySequence
from PySide6.QtWidgets import (
    QAbstractButton,
    QApplication,
    QDockWidget,
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
from app.errors import log_failure, one_line
from app.offsets import OffsetController
from app.panels.deviation_panel import DeviationPanel
from app.panels.document_tree import DocumentTree
from app.panels.fit_panel import POLICY_TEXT, FitSettingsPanel
from app.panels.knot_panel import KnotPanel
from app.panels.log_panel import LogPanel
from app.panels.loss_plot import LossPlot
from app.panels.message_bar import MessageStatusBar
from app.panels.network_quality_panel import NetworkQualityPanel
from app.panels.offset_panel import OffsetPanel
from app.panels.patches_panel import ModeSelector, PatchesPanel
from app.panels.quality_panel import QualityPanel
from app.panels.solid_panel import SolidPanel
from app.part_controller import PartController
from app.patch_controller import PatchController
from app.patch_view import PatchView
from app.state import Document
from app.viewport.scene import SceneView
from app.window.export_policy import ExportPolicy
from app.window.fit_display import FitDisplay
from app.window.history_policy import HistoryPolicy
from app.window.job_indicator import JobIndicator
from app.window.load_policy import LoadPolicy, RecentFiles
from app.window.run_labels import RunLabels
from app.window.selection_policy import SelectionPolicy
from app.window.session_policy import SessionPolicy
from app.window.settings_policy import SettingsPolicy
from app.window.solid_policy import SolidPolicy
from app.window.units_policy import UnitsPolicy
from app.window.up_axis_policy import UpAxisPolicy
from app.workers.jobs import JobRunner

log = logging.getLogger("app")

FIT_AS_PATCHES = "Fit as patches"


def freeze_long_lived_objects():
    """Move everything alive now (torch, VTK, Qt and their modules) out of the garbage collector's
    reach.

    A full (generation 2) collection otherwise walks all of those objects with the GIL held: we
    measured 270 ms in the GUI thread and 690 ms in the fit worker, each a frozen event loop. Only
    objects created later are scanned after ``gc.freeze()``.
    """
    gc.collect()
    gc.freeze()


#: the window's size on a first start, on screens that hold it
DEFAULT_SIZE = (1400, 900)


def initial_size() -> QSize:
    """:data:`DEFAULT_SIZE` within the primary screen's available area: on a 1280 x 800 screen
    the window opened 1400 x 900 and the bottom docks (Patch quality, Deviation), their tabs and
    the status bar were off the screen."""
    width, height = DEFAULT_SIZE
    screen = QGuiApplication.primaryScreen()
    if screen is not None:
        available = screen.availableGeometry()
        width, height = min(width, available.width()), min(height, available.height())
    return QSize(width, height)


def _shortcut_rows(menu) -> list[tuple[str, str]]:
    """(what, keys) of the actions with a shortcut in a menu and its submenus."""
    rows: list[tuple[str, str]] = []
    if menu is None:
        return rows
    for action in menu.actions():
        if action.menu() is not None:
            rows += _shortcut_rows(action.menu())
        elif not action.shortcut().isEmpty():
            rows.append((action.text().replace("&", "").rstrip("."),
                         action.shortcut().toString(QKeySequence.SequenceFormat.NativeText)))
    return rows


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
    session_saved = Signal(str, bool)  # path, success (False: failed or cancelled)
    offsets_updated = Signal(bool)
    error_shown = Signal(str)

    def __init__(self, settings_store: QSettings | None = None):
        super().__init__()
        self.setWindowTitle("NURBS Studio")
        if ICON_FILE.is_file():
            self.setWindowIcon(QIcon(str(ICON_FILE)))
        self.resize(initial_size())
        self.setAcceptDrops(True)
        # long messages end in "..." before the permanent labels, whole in the tooltip
        self.setStatusBar(MessageStatusBar(self))
        self._store = settings_store or QSettings("NURBS Studio", "nurbs-studio")
        self._store.setAtomicSyncRequired(True)  # Qt writes it through QSaveFile: all or nothing
        self.recent = RecentFiles(self._store)
        self._is_shut_down = False
        self._message_box: QMessageBox | None = None
        self.shortcuts_box: QMessageBox | None = None
        self.fit_as_patches_button: QAbstractButton | None = None
        #: a refused single patch goes on as a network once its run has ended
        self._network_after_refusal = False
        self.last_error = ""

        self.document = Document(self)
        self.controller = FitController(self.document, self)
        self.patch_controller = PatchController(self.document, self)
        self.document.network_report_source = self.patch_controller.network_report
        self.jobs = JobRunner(self)
        self.part_controller = PartController(self.document, self.jobs, self)
        self.scene = SceneView(self)
        # the policies: what loading, a settings edit, export, sessions and a fit's progress
        # change (they use the widgets built below, once they exist)
        self.load_policy = LoadPolicy(self, self.recent)
        self.settings_policy = SettingsPolicy(self)
        self.export_policy = ExportPolicy(self)
        self.session_policy = SessionPolicy(self)
        self.fit_display = FitDisplay(self)
        self.selection_policy = SelectionPolicy(self)
        self.history_policy = HistoryPolicy(self)
        self.units_policy = UnitsPolicy(self)
        self.solid_policy = SolidPolicy(self)
        self.up_axis_policy = UpAxisPolicy(self.scene, self._store, self)
        self.setCentralWidget(self._native_container(self.scene.widget))

        self._build_docks()
        self.document.loss_history_source = self.loss_plot.history
        self.offsets = OffsetController(self.document, self.jobs, self.scene, self.offset_panel,
                                        self.report, self)
        self.offsets.offsets_updated.connect(self.offsets_updated)
        self.offsets.offsets_updated.connect(lambda _ok: self.rebuild_tree())
        self._build_actions()
        self._build_menus()
        self._build_status_bar()
        self.run_labels = RunLabels(self.status_labels, self.document.settings.fit_mode)
        self.document.run_texts_source = self.run_labels.kept_texts
        self.patch_view = PatchView(self.patch_controller, self.scene, self.network_quality_panel,
                                    self.status_labels, self.report, self)
        self._connect()
        self.settings_policy.show(self.document.settings)
        self.units_policy.on_units_changed()
        self.update_fit_actions("idle")
        self.selection_policy.on_selection_changed()
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
        self.deviation_panel = DeviationPanel()
        self.solid_panel = SolidPanel(self.document.edit_settings)
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
        self.deviation_dock = self._dock("Deviation", self.deviation_panel, bottom,
                                         "deviation_dock", True)
        self.solid_dock = self._dock("Solid", self.solid_panel, bottom, "solid_dock", True)
        self.log_dock = self._dock("Log", self.log_panel, bottom, "log_dock")
        self.splitDockWidget(self.loss_dock, self.quality_dock, Qt.Orientation.Horizontal)
        self.splitDockWidget(self.quality_dock, self.log_dock, Qt.Orientation.Horizontal)
        self.tabifyDockWidget(self.quality_dock, self.network_quality_dock)
        self.tabifyDockWidget(self.network_quality_dock, self.deviation_dock)
        self.tabifyDockWidget(self.deviation_dock, self.solid_dock)
        self.quality_dock.raise_()
        self.resizeDocks([self.tree_dock, self.fit_dock], [240, 330], Qt.Orientation.Horizontal)
        # the Quality dock's rows need about 510 px with units: 44% of the width keeps them
        # whole (no horizontal scroll bar) down to a 1280-px-wide window
        self.resizeDocks([self.loss_dock, self.quality_dock, self.log_dock], [390, 620, 390],
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
        self.open_action = self._action("&Open...", self.load_policy.open_dialog,
                                        QKeySequence.StandardKey.Open, pixmap.SP_DialogOpenButton)
        self.demo_action = self._action("Open &Demo", self.open_demo)
        # cancels the job the status bar shows (reading files or a session, saving a session)
        self.cancel_load_action = self._action("&Cancel Loading",
                                               lambda *_: self.job_indicator.cancel(),
                                               QKeySequence(Qt.Key.Key_Escape),
                                               pixmap.SP_DialogCancelButton)
        self.cancel_load_action.setToolTip("Stop reading or saving (Esc); the document and "
                                           "the files stay as they were")
        self.cancel_load_action.setEnabled(False)
        self.open_session_action = self._action("Open &Session...", self.session_policy.open_dialog)
        self.save_session_action = self._action("&Save Session...", self.session_policy.save_dialog,
                                                QKeySequence.StandardKey.Save,
                                                pixmap.SP_DialogSaveButton)
        self.screenshot_action = self._action("Save Screens&hot...", self.export_policy.screenshot_dialog)
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
        # the toolbar's buttons keep their short label ("Undo Crop to 1,234 selected points"
        # would crowd the toolbar, and was elided): what they undo is in the tooltip, the
        # Edit menu says it in full
        self.undo_action.setIconText("Undo")
        self.redo_action.setIconText("Redo")
        self.layer_actions = {}
        for layer, text, on in (("cloud", "Point Cloud", True), ("surface", "Fitted Surface", True),
                                ("curve", "Fitted Curve", True),
                                ("control_net", "Control Net", False),
                                ("knot_lines", "Knot Lines", True), ("patches", "Patches", True),
                                ("offsets", "Offsets", True), ("network", "Patch Network", True),
                                ("layout", "Patch Layout", True), ("solid", "Solid", True)):
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
        # CAD's standard views on the number keys (Blender's layout: Ctrl for the opposite side)
        self.view_actions = {
            name: self._action(text, lambda _=False, name=name: self.scene.standard_view(name), key)
            for name, text, key in (("front", "&Front", "1"), ("back", "&Back", "Ctrl+1"),
                                    ("right", "&Right", "3"), ("left", "&Left", "Ctrl+3"),
                                    ("top", "&Top", "7"), ("bottom", "B&ottom", "Ctrl+7"),
                                    ("iso", "&Isometric", "0"))}
        self._build_selection_actions()
        self.shortcuts_action = self._action("&Keyboard Shortcuts", self.show_shortcuts, "F1")
        self.about_action = self._action("&About NURBS Studio", self.show_about)

    def _build_selection_actions(self):
        """The selection tools (checkable, at most one on) and the Edit menu's selection and
        point edits (:class:`SelectionPolicy` does them)."""
        policy = self.selection_policy
        group = QActionGroup(self)
        group.setExclusionPolicy(QActionGroup.ExclusionPolicy.ExclusiveOptional)
        self.selection_tool_actions = {}
        for kind, text, key, tip in (
                ("box", "&Box Select", "S", "Drag a rectangle to select the points inside it"),
                ("lasso", "&Lasso Select", "L", "Draw around the points to select them")):
            action = self._action(text, lambda checked, kind=kind: policy.tool_toggled(
                kind, checked), key, checkable=True)
            action.setToolTip(f"{tip}, through the whole depth ({key}; Shift adds, Ctrl "
                              "removes, Esc clears)")
            group.addAction(action)
            self.selection_tool_actions[kind] = action
        self.selection_actions = {
            "select_all": self._action("Select &All Points", policy.select_all,
                                       QKeySequence.StandardKey.SelectAll),
            "invert": self._action("&Invert Selection", policy.invert, "Ctrl+I"),
            "clear": self._action("&Clear Selection", policy.clear,
                                  QKeySequence(Qt.Key.Key_Escape)),
            "crop": self._action("Crop to Selectio&n", policy.crop, "Ctrl+K"),
            "delete": self._action("&Delete Selection", policy.delete,
                                   QKeySequence(Qt.Key.Key_Delete)),
        }
        # the toolbar shows short labels (the whole toolbar fits 1280 pixels), the menus the
        # full ones
        for action, short in ((self.selection_tool_actions["box"], "Box"),
                              (self.selection_tool_actions["lasso"], "Lasso"),
                              (self.selection_actions["crop"], "Crop"),
                              (self.selection_actions["delete"], "Delete")):
            action.setIconText(short)
        self.selection_actions["crop"].setToolTip("Keep only the selected points (Ctrl+Z undoes)")
        self.selection_actions["delete"].setToolTip("Remove the selected points, e.g. outliers "
                                                    "(Ctrl+Z undoes)")
        self.box_select_action = self.selection_tool_actions["box"]
        self.lasso_select_action = self.selection_tool_actions["lasso"]
        self.invert_selection_action = self.selection_actions["invert"]
        self.clear_selection_action = self.selection_actions["clear"]
        self.crop_action = self.selection_actions["crop"]
        self.delete_selection_action = self.selection_actions["delete"]
        # Esc cancels a load while one runs, else clears the selection
        self.cancel_load_action.changed.connect(policy.update_actions)

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
                                      self.export_policy.dialog(label, suffix))
            self.export_menu.addAction(action)
            self.export_actions[suffix] = action
        self.report_action = self._action("Export Deviation &Report...",
                                          self.export_policy.report_dialog)
        file_menu.addAction(self.report_action)
        file_menu.addAction(self.screenshot_action)
        file_menu.addSeparator()
        file_menu.addAction(self.quit_action)

        edit_menu = bar.addMenu("&Edit")
        edit_menu.addAction(self.undo_action)
        edit_menu.addAction(self.redo_action)
        edit_menu.addSeparator()
        for action in self.selection_tool_actions.values():
            edit_menu.addAction(action)
        for name in ("select_all", "invert", "clear"):
            edit_menu.addAction(self.selection_actions[name])
        edit_menu.addSeparator()
        edit_menu.addAction(self.selection_actions["crop"])
        edit_menu.addAction(self.selection_actions["delete"])
        edit_menu.addSeparator()
        self.units_menu = edit_menu.addMenu("U&nits")
        self.units_policy.fill_menu(self.units_menu)

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
        standard = view_menu.addMenu("&Standard Views")
        for action in self.view_actions.values():
            standard.addAction(action)
        self.up_axis_menu = view_menu.addMenu("&Up Axis")
        self.up_axis_policy.fill_menu(self.up_axis_menu)
        view_menu.addSeparator()
        for dock in (self.tree_dock, self.fit_dock, self.knot_dock, self.offset_dock,
                     self.patches_dock, self.loss_dock, self.quality_dock,
                     self.network_quality_dock, self.deviation_dock, self.solid_dock,
                     self.log_dock):
            view_menu.addAction(dock.toggleViewAction())

        help_menu = bar.addMenu("&Help")
        help_menu.addAction(self.shortcuts_action)
        help_menu.addAction(self.about_action)

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
        toolbar.addSeparator()
        toolbar.addWidget(QLabel(" Units "))
        toolbar.addWidget(self.units_policy.box)
        select_bar = self.addToolBar("Select")
        select_bar.setObjectName("select_toolbar")
        select_bar.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextOnly)
        for action in self.selection_tool_actions.values():
            select_bar.addAction(action)
        select_bar.addAction(self.selection_actions["crop"])
        select_bar.addAction(self.selection_actions["delete"])

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
        self.load_indicator.hide()  # shown while a load or a session's save runs
        self.job_indicator = JobIndicator(self.load_indicator, self.load_progress,
                                          self.cancel_load_action, self)
        self.status_labels = {}
        selection = QLabel("")  # "12,345 of 1,000,000 points selected" while any are
        selection.setStyleSheet("QLabel { background: #ffc400; color: #111111; "
                                "padding: 0px 6px; border-radius: 3px; }")  # the highlight's
        selection.setToolTip("Start fits only the selected points; Esc clears the selection")
        selection.hide()
        self.statusBar().addPermanentWidget(selection)
        self.status_labels["selection"] = selection
        for name, width in (("state", 90), ("iteration", 130), ("loss", 140), ("rate", 100),
                            ("remaining", 120)):
            label = QLabel("-")
            label.setMinimumWidth(width)
            self.statusBar().addPermanentWidget(label)
            self.status_labels[name] = label

    def _connect(self):
        doc, ctl = self.document, self.controller
        doc.settings_changed.connect(self.settings_policy.on_settings_changed)
        self.deviation_panel.style_changed.connect(
            lambda mode, limit, tolerance: self.scene.set_deviation_style(
                mode, limit or None, tolerance or None))
        doc.points_changed.connect(self.selection_policy.on_points_changed)
        doc.shapes_restored.connect(self.history_policy.on_shapes_restored)
        doc.selection_changed.connect(self.selection_policy.on_selection_changed)
        self.scene.selection_tool.region_drawn.connect(self.selection_policy.on_region_drawn)
        doc.content_changed.connect(self.fit_display.on_content_changed)
        doc.units_changed.connect(self.units_policy.on_units_changed)
        doc.fitted_changed.connect(self.fit_display.on_fitted_changed)
        ctl.state_changed.connect(self.update_fit_actions)
        ctl.state_changed.connect(self.fit_display.on_state_changed)
        self.patch_controller.state_changed.connect(self.update_fit_actions)
        self.patch_controller.snapshot_shown.connect(self.fit_display.on_patch_snapshot)
        self.patch_controller.losses_received.connect(self.loss_plot.append)
        ctl.snapshot_shown.connect(self.fit_display.on_snapshot_shown)
        ctl.losses_received.connect(self.loss_plot.append)
        ctl.progress_changed.connect(self.fit_display.on_progress)
        ctl.fit_finished.connect(self.fit_display.on_fit_finished)
        ctl.fit_failed.connect(self._on_fit_failed)
        ctl.fit_finished.connect(self._on_fit_finished)
        ctl.state_changed.connect(self._start_network_after_refusal)
        self.part_controller.state_changed.connect(self._start_network_after_refusal)
        self.solid_policy.connect()

    @Slot(str)
    def _on_fit_failed(self, message: str):
        """A single-patch fit failed. A cloud one patch cannot hold (closed, handles) goes on
        as a network of patches at once (the automatic route: no dead end; Undo returns to one
        patch) unless the user forced a single patch; anything else is reported."""
        if (self.controller.failure_needs_patches
                and not self.document.settings.fit.single_patch):
            if self.solid_policy.after_refusal():  # a machined part: a solid (auto)
                return
            self.report("One open patch cannot hold this cloud: fitting it as a network of "
                        "patches (Patches mode; Undo returns to one patch).")
            self.go_on_as_network()
            return
        self.report(message, error=True, offer_patches=self.controller.failure_needs_patches)

    @Slot(object)
    def _on_fit_finished(self, snapshot) -> None:
        """A single patch finished. When it does not hold the surface cleanly (folds, overlaps,
        an uncovered part: :func:`nurbs_core.route.single_patch_problems`, the route's own
        test) and the user did not force one patch, the cloud goes on as a network of patches
        (open or closed), as the command line's automatic route does; Undo returns to it."""
        from nurbs_core.route import single_patch_problems

        if (snapshot.display.kind != "surface" or self.document.settings.fit.single_patch
                or self.document.settings.fit_mode != "single"):
            return
        problems = single_patch_problems(snapshot.status, snapshot.statistics)
        if not problems:
            return
        self.report(f"One patch does not hold this cloud cleanly ({problems}): fitting it as "
                    "a network of patches (Patches mode; Undo returns to one patch).")
        self.go_on_as_network()

    def go_on_as_network(self) -> None:
        """Switch to Patches mode (one undoable step with the network) and fit the network as
        soon as the single patch's run has ended (a refused run's thread ends just after its
        refusal)."""
        self.document.begin_fit_as_patches()
        self._network_after_refusal = True
        self._start_network_after_refusal()

    @Slot(str)
    def _start_network_after_refusal(self, *_state):
        if self._network_after_refusal and not self.is_fitting():
            self._network_after_refusal = False
            self.start_fit()

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

    # --- loading (the load policy decides) -----------------------------------------------------
    def open_files(self, paths: list[str]) -> bool:
        """Read the files in an abandonable worker thread; the document changes only if every
        file reads. A load still running is cancelled (the newest request wins). Every load
        started here ends with one ``files_loaded``: True when applied, False when it failed or
        was cancelled (none when the window closes first)."""
        return self.load_policy.open_files(paths)

    def is_loading(self) -> bool:
        return self.load_policy.is_loading()

    def cancel_load(self, *_args, quiet: bool = False) -> bool:
        """Abandon the load in progress (Cancel, Esc): returns at once and loads nothing; the
        reader thread is left to end on its own and its result is dropped. quiet: no report
        (the caller tells the user). False when no load runs."""
        return self.load_policy.cancel(quiet=quiet)

    @property
    def load_message(self) -> str:
        """One line: how the latest load ended (opened, failed, cancelled)."""
        return self.load_policy.message

    def open_demo(self) -> bool:
        return self.open_files([str(demo_path())])

    def recent_files(self) -> list[str]:
        return self.recent.paths()

    def _fill_recent_menu(self):
        self.recent.fill_menu(self.recent_menu, self.open_files)

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
    def rebuild_tree(self):
        """The document tree lists what the document holds and what is on show."""
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
        self.rebuild_tree()

    def set_deviation_visible(self, visible: bool):
        self.scene.set_deviation_visible(visible)
        _set_checked_quietly(self.deviation_action, visible)
        self.rebuild_tree()

    def set_quality_visible(self, visible: bool):
        """Paint the fitted surface by its quality map (flipped, overlapping, far)."""
        self.scene.set_quality_visible(visible)
        _set_checked_quietly(self.quality_action, visible)
        self.rebuild_tree()

    def set_seam_visible(self, visible: bool):
        """Colour the patch network by its seam angles (with a colour bar in degrees)."""
        self.scene.network.set_seam_visible(visible)
        _set_checked_quietly(self.seam_action, visible)
        self.rebuild_tree()

    def set_target_visible(self, index: int, visible: bool):
        """Hide a cloud from the view and from the fit target (applies to the next run); the
        selection (of the visible points) is cleared."""
        self.document.set_selection(None)
        self.document.targets[index].visible = visible
        self.scene.set_cloud(self.document.target_points())
        self.knot_panel.set_points(self.document.target_points())
        role = "part of" if visible else "left out of"
        self.report(f"{self.document.targets[index].name} is {role} the fit target from the "
                    "next Start.")

    # --- fit -------------------------------------------------------------------------------------
    def active_controller(self) -> FitController | PatchController | PartController:
        """The controller of the fit mode on show (what Start, Pause, Stop and Reset drive); the
        part route's while it runs (Stop cancels it)."""
        mode = self.document.settings.fit_mode
        if mode == "solid" or self.part_controller.is_busy():
            return self.part_controller
        return self.patch_controller if mode == "patches" else self.controller

    def is_fitting(self) -> bool:
        """Whether any fit (one patch, a network, a solid) runs."""
        return (self.controller.is_busy() or self.patch_controller.is_busy()
                or self.part_controller.is_busy())

    def start_fit(self, *_args) -> bool:
        """Start the fit of the current mode (not while another fit still runs): in Solid mode
        (or Single patch with "Solid from analytic faces" on) the part route."""
        if self.is_fitting():
            return False
        if self.document.selection is not None:
            self.statusBar().showMessage(
                f"Fitting the {self.document.selected_count():,} selected points only (Esc "
                "clears the selection: Start then fits every point)", 8000)
        if self.solid_policy.starts_with_solid():
            return self.solid_policy.start_for_start()
        if (self.document.several_curves and self.document.selection is None
                and self.active_controller() is self.controller):
            # one live fit holds one shape: over all the curves it would jump between them
            self.report(f"The cloud holds {self.document.several_curves} curves, each fitted "
                        "when it opened (the document tree lists them; File > Export writes "
                        "them all). Start fits one curve live: select its points (Box or "
                        "Lasso), then Start.")
            return False
        if self.active_controller() is self.patch_controller:
            self.network_quality_dock.raise_()
            # (its step keeps the curve shown before it: cleared once the run has begun)
            started = self.patch_controller.start()
            if started:
                self.loss_plot.clear()  # a network starts from the cloud: a new curve
            return started
        return self.controller.start()

    def fit_as_patches(self) -> bool:
        """Switch to Patches mode and start the patch fit: one undoable step with the network."""
        if self._message_box is not None:
            self._message_box.reject()
        self.document.begin_fit_as_patches()
        return self.start_fit()

    def reset_fit(self):
        """Stop the mode's fit and discard its shape: an undoable step (Undo brings back the
        shape from before a fit that was under way; that fit's result is dropped)."""
        controller = self.active_controller()
        if controller is self.part_controller:
            self.solid_policy.reset()
            return
        before = controller.fit_before or self.document.shape_state()
        if controller is self.patch_controller:
            self.reset_patch_network()
            self.report("Reset: the patch network was discarded (Undo brings it back).")
        else:
            self.controller.reset()
            self.loss_plot.clear()
            self.report("Reset: the next Start initializes a new shape (Undo brings the "
                        "discarded one back).")
        self.document.record_shapes(before, "Reset")

    def reset_patch_network(self):
        """Stop and discard the patch network (its fit, view, loss curve and tree entry)."""
        self.patch_controller.reset()
        self.loss_plot.clear()
        self.patch_view.clear()
        if self.scene.deviation_map() is not None:  # it measured the network just discarded
            self.scene.set_deviation(None, mode="patches")
            self.fit_display.refresh_deviation_panel()
        self.rebuild_tree()

    @Slot(str)
    def update_fit_actions(self, *_state):
        """Either controller's state changed: the actions follow the active one's (Start waits
        until neither runs)."""
        active = self.active_controller()
        state = active.state
        busy = self.is_fitting() or state != "idle"
        can_pause = active is not self.part_controller
        self.start_action.setEnabled(not busy)
        self.pause_action.setEnabled(state == "running" and can_pause)
        self.resume_action.setEnabled(state == "paused")
        self.stop_action.setEnabled(state in ("running", "paused"))
        self.status_labels["state"].setText(state.capitalize())
        if state == "paused":
            self.knot_panel.show_state(self.document.settings.fit, self.document.fitted)

    # --- export and sessions (their policies decide) ------------------------------------------
    def export_to(self, path: str) -> bool:
        """Write what the mode shows: the patch network in Patches mode, else the fitted shape,
        loaded patches and offsets."""
        return self.export_policy.export_to(path)

    def export_network(self, path: str) -> bool:
        """Write the patch network with ``nurbs_core.io.write_network`` (format from the suffix:
        one joined B-rep in .3dm, a sewn solid in .step / .iges, our .json, a welded mesh)."""
        return self.export_policy.export_network(path)

    def export_solid(self, path: str) -> bool:
        """Write the solid of Solid mode with ``nurbs_core.io.solid_io.save_solid`` (.step,
        .iges, .brep, .stl, .obj, .ply; atomic)."""
        return self.solid_policy.export(path)

    def save_session(self, path: str) -> bool:
        """Save the session in a job, atomically (ends with ``session_saved(path, ok)``): on
        failure or cancel the user is told and an existing file at
        ``path`` is left byte for byte as it was."""
        return self.session_policy.save(path)

    def open_session(self, path: str) -> bool:
        """Open a session in a load job (ends with ``files_loaded(ok)``); a file that does not
        read leaves the document and the fit unchanged."""
        return self.load_policy.open_session(path)

    def shortcut_table(self) -> list[tuple[str, str]]:
        """(what, keys) of every action with a shortcut, in menu order: Help > Keyboard
        Shortcuts shows them."""
        rows = []
        for menu_action in self.menuBar().actions():
            rows += _shortcut_rows(menu_action.menu())
        return rows

    def show_shortcuts(self):
        rows = self.shortcut_table()
        text = "\n".join(f"{keys:<12} {what}" for what, keys in rows)
        box = QMessageBox(QMessageBox.Icon.NoIcon, "Keyboard shortcuts", text,
                          QMessageBox.StandardButton.Close, self)
        box.setStyleSheet("QLabel { font-family: monospace; }")
        box.open()
        self.shortcuts_box = box

    def about_text(self) -> str:
        from importlib.metadata import PackageNotFoundError, version

        try:
            release = version("nurbs-studio")
        except PackageNotFoundError:
            release = "(not installed)"
        return (f"<h3>NURBS Studio {release}</h3>"
                "<p>Scans to clean NURBS surfaces, watertight patch networks and CAD solids, "
                "live and differentiable, after NURBS-Diff (Prasad et al.).</p>"
                "<p>Open source: the engine is <tt>nurbs_core</tt>, the window PySide6 and "
                "pyvista. Its command line is <tt>nurbs-fit</tt>; <tt>nurbs-fit --help</tt> lists "
                "every option.</p>")

    def show_about(self):
        QMessageBox.about(self, "About NURBS Studio", self.about_text())

    def export_report(self, path: str) -> bool:
        """Write a deviation report (.html or .pdf) of what the mode shows against the clouds."""
        return self.export_policy.export_report(path)

    def result_status(self) -> tuple[str, list[str]]:
        """The status of the result the mode shows and its warnings, as the headline says."""
        if self.document.settings.fit_mode == "solid":
            solid = self.document.solid
            if solid is None:
                return "no solid", []
            return solid.report.status, list(solid.report.problems)
        if self.document.settings.fit_mode == "patches":
            shown = self.patch_controller.latest_shown
            if shown is None or not shown.done:
                return "fit in progress", []
            from nurbs_core.status import reported_status

            return reported_status("converged", list(shown.warnings)), list(shown.warnings)
        snapshot = self.controller.latest_shown
        if snapshot is None or not snapshot.done:
            return "fit in progress", []
        return str(snapshot.status), []

    def save_screenshot(self, path: str) -> bool:
        """The whole window (viewport included) as an image (PNG; the format follows the
        suffix), written atomically: on failure an existing file is left as it was."""
        return self.export_policy.save_screenshot(path)

    # --- shutdown --------------------------------------------------------------------------------
    def live_timers(self) -> int:
        return (self.controller.live_timers() + self.patch_controller.live_timers()
                + self.part_controller.live_timers()
                + self.scene.live_timers()
                + self.loss_plot.live_timers() + self.job_indicator.live_timers())

    def shutdown(self):
        """Stop the worker, jobs and timers and release the render window; idempotent.

        A load in progress is abandoned, not waited for (its reader may never return); the fit
        workers stop at their next iteration and are joined; short jobs (an export) complete."""
        if self._is_shut_down:
            return
        self._is_shut_down = True
        self.load_policy.shut_down()
        self.job_indicator.shut_down()
        self.fit_panel.cancel_pending()
        self.patches_panel.cancel_pending()
        self.controller.shutdown()
        self.patch_controller.shutdown()  # joined before the render window goes
        self.part_controller.shutdown()  # abandoned: its result is dropped
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
