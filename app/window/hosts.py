"""What each of the window's parts may reach of the window: one narrow protocol per part.

The parts (:mod:`app.window.export_policy`, ``load_policy``, ``session_policy``,
``settings_policy``, ``selection_policy``, ``history_policy``, ``units_policy``,
``fit_display``) are owned by
:class:`app.main_window.MainWindow`, which satisfies every protocol here (a test checks it on
the real window); they never import it. A part that needs more of the window says so here
first.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    from PySide6.QtCore import SignalInstance
    from PySide6.QtGui import QAction
    from PySide6.QtWidgets import QDockWidget, QLabel, QStatusBar

    from app.controller import FitController
    from app.offsets import OffsetController
    from app.panels.deviation_panel import DeviationPanel
    from app.panels.document_tree import DocumentTree
    from app.panels.fit_panel import FitSettingsPanel
    from app.panels.knot_panel import KnotPanel
    from app.panels.loss_plot import LossPlot
    from app.panels.network_quality_panel import NetworkQualityPanel
    from app.panels.offset_panel import OffsetPanel
    from app.panels.patches_panel import ModeSelector, PatchesPanel
    from app.panels.quality_panel import QualityPanel
    from app.panels.solid_panel import SolidPanel
    from app.part_controller import PartController
    from app.patch_controller import PatchController
    from app.state import Document
    from app.viewport.scene import SceneView
    from app.window.job_indicator import JobIndicator
    from app.window.run_labels import RunLabels
    from app.workers.jobs import JobRunner


@runtime_checkable
class RecentDirectories(Protocol):
    def last_directory(self) -> str: ...


@runtime_checkable
class Reporter(Protocol):
    """Tells the user: the log, the status bar and, for errors, a dialog."""

    def report(self, message: str, error: bool = False, offer_patches: bool = False,
               exc: BaseException | None = None) -> Any: ...


@runtime_checkable
class ExportHost(Reporter, Protocol):
    document: Document
    recent: RecentDirectories
    jobs: JobRunner
    scene: SceneView
    loss_plot: LossPlot
    deviation_panel: DeviationPanel
    export_finished: SignalInstance

    def grab(self) -> Any: ...
    def export_to(self, path: str) -> bool: ...
    def export_network(self, path: str) -> bool: ...
    def export_solid(self, path: str) -> bool: ...
    def export_report(self, path: str) -> bool: ...
    def result_status(self) -> tuple[str, list[str]]: ...
    def save_screenshot(self, path: str) -> bool: ...


@runtime_checkable
class SessionOpener(Protocol):
    """What becomes of a session file the load policy has read (the session policy)."""

    def apply(self, path: str, session: dict[str, Any]) -> None: ...
    def failed(self, path: str, exc: BaseException) -> None: ...


@runtime_checkable
class SolidOpener(Protocol):
    """What becomes of a solid a load opened from a file (the solid policy)."""

    def show_opened(self) -> str: ...


@runtime_checkable
class LoadHost(Reporter, Protocol):
    document: Document
    controller: FitController
    part_controller: PartController
    solid_policy: SolidOpener
    jobs: JobRunner
    job_indicator: JobIndicator
    session_policy: SessionOpener
    loss_plot: LossPlot
    files_loaded: SignalInstance
    status_labels: dict[str, QLabel]
    run_labels: RunLabels

    def statusBar(self) -> QStatusBar: ...  # noqa: N802 (Qt's name)
    def setWindowTitle(self, title: str) -> None: ...  # noqa: N802 (Qt's name)
    def reset_patch_network(self) -> None: ...
    def open_files(self, paths: list[str]) -> bool: ...
    def open_session(self, path: str) -> bool: ...


@runtime_checkable
class SessionHost(Reporter, Protocol):
    document: Document
    controller: FitController
    patch_controller: PatchController
    part_controller: PartController
    loss_plot: LossPlot
    recent: RecentDirectories
    jobs: JobRunner
    job_indicator: JobIndicator
    session_saved: SignalInstance

    def statusBar(self) -> QStatusBar: ...  # noqa: N802 (Qt's name)

    def reset_patch_network(self) -> None: ...
    def save_session(self, path: str) -> bool: ...
    def open_session(self, path: str) -> bool: ...


@runtime_checkable
class SettingsHost(Protocol):
    document: Document
    controller: FitController
    patch_controller: PatchController
    scene: SceneView
    deviation_panel: DeviationPanel
    offsets: OffsetController
    fit_panel: FitSettingsPanel
    knot_panel: KnotPanel
    offset_panel: OffsetPanel
    patches_panel: PatchesPanel
    mode_selector: ModeSelector
    fit_dock: QDockWidget
    knot_dock: QDockWidget
    offset_dock: QDockWidget
    patches_dock: QDockWidget
    quality_dock: QDockWidget
    network_quality_dock: QDockWidget
    part_controller: PartController
    solid_panel: SolidPanel
    solid_dock: QDockWidget
    run_labels: RunLabels
    def statusBar(self) -> QStatusBar: ...  # noqa: N802 (Qt's name)
    def rebuild_tree(self) -> None: ...
    def update_fit_actions(self, *_state: object) -> None: ...


@runtime_checkable
class FitDisplayHost(Reporter, Protocol):
    document: Document
    patch_controller: PatchController
    scene: SceneView
    jobs: JobRunner
    offsets: OffsetController
    deviation_panel: DeviationPanel
    quality_panel: QualityPanel
    knot_panel: KnotPanel
    loss_plot: LossPlot
    tree: DocumentTree
    status_labels: dict[str, QLabel]

    def rebuild_tree(self) -> None: ...


@runtime_checkable
class UnitsHost(Reporter, Protocol):
    document: Document
    scene: SceneView
    quality_panel: QualityPanel
    network_quality_panel: NetworkQualityPanel
    offset_panel: OffsetPanel
    fit_panel: FitSettingsPanel
    deviation_panel: DeviationPanel

    def rebuild_tree(self) -> None: ...


class StoppedByEdit(Protocol):
    """What the history policy asks of the selection policy."""

    def take_stopped(self) -> list[str]: ...


@runtime_checkable
class HistoryHost(Reporter, Protocol):
    document: Document
    controller: FitController
    patch_controller: PatchController
    loss_plot: LossPlot
    run_labels: RunLabels
    selection_policy: StoppedByEdit

    def rebuild_tree(self) -> None: ...
    def reset_patch_network(self) -> None: ...


@runtime_checkable
class SelectionHost(Reporter, Protocol):
    document: Document
    controller: FitController
    patch_controller: PatchController
    part_controller: PartController
    scene: SceneView
    knot_panel: KnotPanel
    status_labels: dict[str, QLabel]
    cancel_load_action: QAction
    #: "box" / "lasso" -> the checkable tool actions
    selection_tool_actions: dict[str, QAction]
    #: "select_all", "invert", "clear", "crop", "delete" -> the Edit menu's actions
    selection_actions: dict[str, QAction]

    def statusBar(self) -> QStatusBar: ...  # noqa: N802 (Qt's name)
    def rebuild_tree(self) -> None: ...
    def reset_patch_network(self) -> None: ...


@runtime_checkable
class SolidHost(Reporter, Protocol):
    document: Document
    part_controller: PartController
    scene: SceneView
    jobs: JobRunner
    solid_panel: SolidPanel
    solid_dock: QDockWidget
    export_finished: SignalInstance

    def rebuild_tree(self) -> None: ...
    def start_fit(self, *_args: object) -> bool: ...
    def go_on_as_network(self) -> None: ...
    def resizeDocks(self, docks: Any, sizes: Any, orientation: Any) -> None: ...  # noqa: N802
    def update_fit_actions(self, *_state: object) -> None: ...
