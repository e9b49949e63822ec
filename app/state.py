"""The document: targets (point clouds), the fitted geometry, loaded patches, offsets, settings.

Pure data plus Qt signals; no torch, no VTK. Settings edits go through a ``QUndoStack`` so every
edit can be undone and redone; so do point edits (crop to the selection, delete the selection),
whose undo also brings back the fitted surface of the points as they were, and the fitted
shapes: a finished (or stopped) fit, a patch network fit and Reset are each one step holding the
shapes before and after (:class:`ShapeState`: control points, no points), pushed when the fit has
ended; a face edit of the solid (merge, split, a type) is one step holding the solids before and
after. Loading files replaces the content and is not an undoable edit. The selection (which
points of the visible clouds are picked) is the document's too, but not an edit: it is not
undone, and Start fits only the selected points while there are any.
Geometry is held as the engine's numpy twins (:mod:`nurbs_core.geometry_arrays`: what
``NurbsCurve.numpy()`` / ``NurbsSurface.numpy()`` return); anything else given to the document is
converted once, on the way in.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QUndoCommand, QUndoStack

from nurbs_core.fitting.config import INITS, FitConfig
from nurbs_core.fitting.config import OPTIMIZERS as OPTIMIZERS
from nurbs_core.fitting.config import PARAMETERIZATIONS as _PARAMETERIZATIONS
from nurbs_core.fitting.config import SOLVERS as _SOLVERS
from nurbs_core.fitting.grid_budget import POINTS_PER_CONTROL_POINT as POINTS_PER_CONTROL_POINT
from nurbs_core.fitting.grid_budget import grid_for_points
from nurbs_core.geometry_arrays import GeometryArrays, from_mapping
from nurbs_core.loss_terms import LOSS_TERMS as LOSS_TERMS  # re-exported for the panels
from nurbs_core.patches.options import PatchOptions

#: Sessions are zip archives (:mod:`app.session_file`); the JSON sessions written before them
#: are still read: this format (nested settings) and the first one (flat settings).
JSON_SESSION_FORMAT = "nurbs-studio-session-v2"
OLD_SESSION_FORMATS = ("nurbs-studio-session-v1",)

#: The choices the panels offer, in display order: the engine's own lists (FitConfig validates
#: against the same tuples). l1 / l2 / mse pair the i-th sample with the i-th point: meaningful
#: only for ordered targets.
INITIALIZATIONS = INITS
#: labels of the engine's solvers and parameterisations of unordered surface clouds
SOLVER_LABELS = {"least_squares": "least squares"}
#: what the stages of a fit's plan (``nurbs_core.fitting.plan.FitPlan.stages``) are called
STAGE_LABELS = {"least_squares": "least-squares core", "gradient": "gradient fit",
                "exact": "exact least squares"}
SOLVERS = tuple((name, SOLVER_LABELS.get(name, name)) for name in _SOLVERS)
PARAMETERIZATIONS = tuple((name, name) for name in _PARAMETERIZATIONS)
#: How Start fits the cloud: one NURBS surface (or curve), or a network of patches over a quad
#: layout (closed objects: ``nurbs_core.patches``).
FIT_MODES = (("single", "Single patch"), ("patches", "Patches"), ("solid", "Solid"))
#: "Solid from analytic faces": whether Start makes a solid of a closed, part-like scan
#: (:func:`nurbs_core.route.choose_route`'s ``part``: auto lets the scan decide)
SOLID_CHOICES = (("auto", "auto"), ("on", "on"), ("off", "off"))
TOLERANCE_HINT = ("Tolerance: a positive distance in the cloud's units (e.g. 0.01), or empty / "
                  "\"auto\" to derive it from the cloud's noise")


def part_argument(solid: str) -> bool | None:
    """``choose_route``'s ``part`` for the "Solid from analytic faces" setting: "auto" -> None
    (the scan decides), "on" -> True (forced), "off" -> False. ValueError for anything else."""
    choices = {"auto": None, "on": True, "off": False}
    if solid not in choices:
        raise ValueError(f"Solid from analytic faces is {solid!r}; choose auto, on or off")
    return choices[solid]


def control_grid_for(point_count: int, fit: FitConfig) -> tuple[int, int] | None:
    """A smaller (n_u, n_v) when the cloud is too small for the fit's surface control grid,
    else None (the engine's rule, :func:`nurbs_core.fitting.grid_budget.grid_for_points`, which
    the command line applies to its default grid too)."""
    return grid_for_points(point_count, fit) if fit.kind == "surface" else None


def parse_tolerance(text: str) -> float | None:
    """``""`` or ``"auto"`` -> None (automatic); ``"0.01"`` -> 0.01. Raises ValueError with
    :data:`TOLERANCE_HINT` for anything else (zero, negative, not a number)."""
    text = text.strip()
    if text.lower() in ("", "auto"):
        return None
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number. {TOLERANCE_HINT}") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{text} is not a positive distance. {TOLERANCE_HINT}")
    return value


#: The offset distance's range (the Offsets dock's spin box, a session's setting), model units.
MAX_OFFSET_DISTANCE = 1e6

@dataclass(frozen=True)
class Settings:
    """Everything the user can edit. Immutable: edits make a new object (undo keeps the old).

    ``fit`` is the engine's own :class:`~nurbs_core.fitting.config.FitConfig` (the one
    description of a single-patch fit, sent to the worker as it is) and ``patches`` its
    :class:`~nurbs_core.patches.options.PatchOptions`; the rest is the window's own: which of
    the two Start runs, and the offsets shown beside a loaded patch set."""

    fit: FitConfig = field(default_factory=FitConfig)
    patches: PatchOptions = field(default_factory=PatchOptions)
    #: "single", "patches" or "solid" (:data:`FIT_MODES`)
    fit_mode: str = "single"
    #: "Solid from analytic faces": "auto", "on" or "off" (:func:`part_argument`)
    solid: str = "auto"
    offset_distance: float = 0.1
    constrain_shared_edges: bool = True
    show_offsets: bool = False

    def to_json(self) -> dict[str, Any]:
        return {"fit": self.fit.to_json(), "patches": self.patches.to_json(),
                **{name: getattr(self, name) for name in WINDOW_FIELDS}}

    def validate(self) -> None:
        """Raise ValueError naming the first bad setting: the fit's and the patch options' own
        checks, then the window's (a text ``"no"`` is not false, ``"0.1"`` not a number)."""
        self.fit.validate()
        self.patches.validate()
        if self.fit_mode not in dict(FIT_MODES):
            raise ValueError(f"fit_mode must be one of {', '.join(dict(FIT_MODES))}; got "
                             f"{self.fit_mode!r}")
        if (isinstance(self.offset_distance, bool)
                or not isinstance(self.offset_distance, (int, float))
                or not np.isfinite(self.offset_distance)):
            raise ValueError(f"offset_distance must be a finite number, got "
                             f"{self.offset_distance!r}")
        if abs(self.offset_distance) > MAX_OFFSET_DISTANCE:
            raise ValueError(f"offset_distance {self.offset_distance:g} is beyond the Offsets "
                             f"dock's range (-{MAX_OFFSET_DISTANCE:g} to "
                             f"{MAX_OFFSET_DISTANCE:g})")
        for name in ("constrain_shared_edges", "show_offsets"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Settings:
        """Inverse of :meth:`to_json`; raises ValueError for unknown settings."""
        unknown = sorted(set(data) - {"fit", "patches"} - WINDOW_FIELDS)
        if unknown:
            raise ValueError(f"unknown settings in session: {', '.join(unknown)}")
        window = {name: data[name] for name in WINDOW_FIELDS if name in data}
        return cls(fit=FitConfig.from_json(data.get("fit", {})),
                   patches=PatchOptions.from_json(data.get("patches", {})), **window)

    @classmethod
    def from_flat_json(cls, data: dict[str, Any]) -> Settings:
        """The settings of a first-format session (one flat dict)."""
        data = dict(data)
        renamed = {"patch_count": "patches", "patch_size": "size",
                   "patch_stiffness": "stiffness", "seam_weight": "seam_weight"}
        patches = {new: data.pop(old) for old, new in renamed.items() if old in data}
        if patches.get("patches", "auto") is None:
            patches["patches"] = "auto"
        window = {name: data.pop(name) for name in WINDOW_FIELDS if name in data}
        return cls(fit=FitConfig.from_json(data), patches=PatchOptions.from_json(patches),
                   **window)


#: The window's own settings (everything in Settings but the fit and the patch options).
WINDOW_FIELDS = frozenset({"fit_mode", "solid", "offset_distance", "constrain_shared_edges",
                           "show_offsets"})
FIT_FIELDS = frozenset(f.name for f in dataclasses.fields(FitConfig))


def with_changes(settings: Settings, **changes: Any) -> Settings:
    """``settings`` with ``changes``: names of FitConfig fields edit the fit (custom knots a
    degree or grid change invalidates are dropped), the window's names edit the window's
    settings. Raises TypeError for any other name."""
    unknown = sorted(set(changes) - FIT_FIELDS - WINDOW_FIELDS)
    if unknown:
        raise TypeError(f"no such setting: {', '.join(unknown)}")
    fit = {name: value for name, value in changes.items() if name in FIT_FIELDS}
    window = {name: value for name, value in changes.items() if name in WINDOW_FIELDS}
    return dataclasses.replace(settings, fit=settings.fit.replace(**fit) if fit else settings.fit,
                               **window)


def grid_setting(fit: FitConfig) -> tuple[int, ...]:
    """The control points per direction the settings ask for: (u, v) for a surface, (u,) for a
    curve."""
    if fit.kind == "surface":
        return fit.control_points_u, fit.control_points_v
    return (fit.control_points_u,)


def control_grid(geometry: GeometryArrays | None) -> tuple[int, ...] | None:
    """(control points u, control points v, degree u, degree v) of a surface, (control points,
    degree) of a curve; None for no shape."""
    if geometry is None:
        return None
    if geometry.kind == "surface":
        count_u, count_v = (int(n) for n in geometry.control_points.shape[:2])
        return count_u, count_v, int(geometry.degree_u), int(geometry.degree_v)
    return int(geometry.control_points.shape[0]), int(geometry.degree)


@dataclass(frozen=True)
class FitAccount:
    """What the fitted shape is and how it was made: one source for the Fit settings dock's
    Result line and the Quality dock's control grid and tolerance rows.

    grid: :func:`control_grid` of the shape (the grid the fit grew to, not the one the settings
    start from); stages: the stages of the plan that made it (``FitPlan.stages``; empty when
    not known: a shape from a session); tolerance: the distance the result was held to (input
    units), None when it was not (the gradient fit), with the engine's verdict and whether it
    was the automatic one; grid_setting: the control points the settings asked for when the
    shape was made (:func:`grid_setting`; None: not known). Start goes on at the shape's own
    grid while the setting is still that one (:func:`app.workers.fit_worker.start_config`)."""

    kind: str
    grid: tuple[int, ...]
    stages: tuple[str, ...] = ()
    tolerance: float | None = None
    tolerance_met: bool = False
    automatic_tolerance: bool = True
    grid_setting: tuple[int, ...] | None = None

    @classmethod
    def of(cls, geometry: GeometryArrays, stages: tuple[str, ...] = (),
           statistics: Mapping[str, float] | None = None,
           automatic_tolerance: bool = True,
           grid_setting: tuple[int, ...] | None = None) -> FitAccount:
        """The account of ``geometry``, made by ``stages`` with the settings' ``grid_setting``,
        whose final measures are ``statistics`` (their "tolerance" and "tolerance_met": the
        core's verdict)."""
        grid = control_grid(geometry)
        assert grid is not None, "a shape"
        statistics = statistics or {}
        tolerance = statistics.get("tolerance")
        return cls(geometry.kind, grid, tuple(stages),
                   None if tolerance is None else float(tolerance),
                   bool(statistics.get("tolerance_met", False)), automatic_tolerance,
                   None if grid_setting is None else tuple(grid_setting))


@dataclass(frozen=True, eq=False)
class FileOrder:
    """A cloud file's points as it lists them, when some repeat an earlier one: ``points``
    (K, 3) in the file's order, repeats kept (what a curve fits, as ``nurbs-fit --curve`` does:
    a closed polyline repeats its first point last), and ``rows`` (M,) int, the row of them each
    point loaded is (the loaded points are each point once: ``points[rows]``)."""

    points: np.ndarray
    rows: np.ndarray


@dataclass(eq=False)
class Target:
    """A point cloud to fit: points (N, 3) float64. A mesh file's cloud (points sampled over
    its triangles when it has few vertices, as ``nurbs-fit`` reads it) keeps the file's own
    closed mesh for the route and a network's layout (``mesh``, a
    :class:`nurbs_core.patches.scan_mesh.ScanMesh`; None for a cloud or a mesh that cannot
    serve, ``mesh_note`` then saying why) while its points are the ones read
    (``read_points``: an edit replaces them, and the mesh no longer stands for them). A cloud
    file whose points repeat is loaded with each point once; ``file_order`` keeps its points
    as listed, for a curve while the points are the ones read."""

    name: str
    points: np.ndarray
    path: str = ""
    visible: bool = True
    mesh: Any = None
    mesh_note: str = ""
    read_points: np.ndarray | None = field(default=None, repr=False)
    file_order: FileOrder | None = field(default=None, repr=False)


@dataclass
class OffsetDisplay:
    surfaces: list[GeometryArrays] = field(default_factory=list)
    max_gap: float = 0.0
    shared_edges: int = 0


def spread_over_cloud(values: np.ndarray, selection: np.ndarray | None) -> np.ndarray:
    """Per-point values of a fit of the selected points (M,) as values of the whole cloud (N,):
    NaN at the points left out (drawn grey, left out of the statistics). selection: bool (N,)
    with M True entries, or None (the values are returned as they are)."""
    values = np.asarray(values)
    if selection is None or len(values) != int(np.count_nonzero(selection)):
        return values
    spread = np.full(len(selection), np.nan)
    spread[selection] = values
    return spread


@dataclass(frozen=True, eq=False)
class LossHistory:
    """The loss plot's curves as they stood (:meth:`app.panels.loss_plot.LossPlot.history`):
    ``iterations`` (n,) the x positions, ``values`` one (n,) series per term and the total (NaN
    where a row had no value). Kept with the shapes of an undo step, so that Undo and Redo show
    the curve of the fit that made the shape shown. 16 bytes a row per term."""

    iterations: np.ndarray
    values: Mapping[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.iterations)


@dataclass(frozen=True)
class ShapeState:
    """The document's fitted shapes as an undo step keeps them: the fitted patch (or curve) with
    its account, and the patch network with what a session keeps of its fit (its report:
    ``PatchController.network_report``), and the loss plot's curves of the fits that made them
    (``loss_history``; None: an empty plot). No points: a step holds the shapes' arrays (9.6 kB
    for the demo's 17 x 17 patch, 21 kB for the 22-patch network of a sphere) and the network
    report, whose deviation has one value per point (8 bytes each, shared with the fit that
    made it, not copied)."""

    fitted: GeometryArrays | None = None
    fitted_account: FitAccount | None = None
    network: Any = None
    network_report: dict[str, Any] | None = None
    loss_history: LossHistory | None = None
    #: the status bar's run labels as the fit that made the shapes left them: (fit mode,
    #: iteration text, loss text); None: not known
    run_texts: tuple[str, str, str] | None = None

    def same_shapes(self, other: ShapeState) -> bool:
        """Whether ``other`` holds these very shapes (a fit that changed nothing: no step)."""
        return self.fitted is other.fitted and self.network is other.network


@dataclass(frozen=True)
class PointsState:
    """What a point edit changes: every target's points (hidden ones too), the selection (bool
    over the visible clouds stacked, or None) with the targets' visibility it was made under,
    and the fitted shapes."""

    points: tuple[np.ndarray, ...]
    selection: np.ndarray | None
    visible: tuple[bool, ...]
    shapes: ShapeState = field(default_factory=ShapeState)


class _ContentCommand(QUndoCommand):
    """An edit of the document's content (its points, its unit): dropped when reached after
    other files were opened (nothing of it is left; they came with their own)."""

    def __init__(self, document: Document, text: str):
        super().__init__(text)
        self._document = document
        self._generation = document.content_generation

    def _current(self) -> bool:
        if self._document.content_generation == self._generation:
            return True
        self.setObsolete(True)
        return False


class _PointsCommand(_ContentCommand):
    """Crop or delete: undo restores the points, the selection and the fitted shape as they were
    before; redo the edited points with the shape fitted to them since (a fit after a crop comes
    back with the crop)."""

    def __init__(self, document: Document, before: PointsState, after: PointsState, text: str):
        super().__init__(document, text)
        self._before, self._after = before, after
        self._pushed = False

    def redo(self):
        if self._current():
            # the push runs redo once: the edit itself, which its policy reports
            self._document._apply_points(self._after, f"Redo {self.text()}" if self._pushed
                                         else "")
        self._pushed = True

    def undo(self):
        if self._current():
            document = self._document
            self._after = dataclasses.replace(self._after, shapes=document.shape_state())
            document._apply_points(self._before, f"Undo {self.text()}")


class _ShapesCommand(_ContentCommand):
    """A fit, a patch network fit, Reset: undo puts back the shapes before, redo the shapes
    after. Pushed once the fit has ended, so its first redo (QUndoStack.push calls it) changes
    nothing. ``settings`` (old, new): the switch to Patches mode that a network fit completes
    (:meth:`Document.begin_fit_as_patches`): applied on push, undone with the shapes; settings
    outlive loaded files, so they are restored even when the shapes are gone."""

    def __init__(self, document: Document, before: ShapeState, after: ShapeState, text: str,
                 settings: tuple[Settings, Settings] | None = None):
        super().__init__(document, text)
        self._before, self._after, self._settings = before, after, settings
        self._pushed = False

    def complete(self, after: ShapeState) -> None:
        """The network fit this switch was made for has ended with ``after``."""
        self._after = after

    def _shapes_current(self) -> bool:
        if self._settings is None:
            return self._current()
        return self._document.content_generation == self._generation

    def redo(self):
        document = self._document
        if self._settings is not None:
            document._apply_settings(self._settings[1])
        if self._pushed and self._shapes_current():
            document._apply_shapes(self._after, f"Redo {self.text()}")
        self._pushed = True

    def undo(self):
        document = self._document
        if document._pending_switch is self:
            document._pending_switch = None  # the fit under way no longer completes it
        if self._shapes_current():
            document._apply_shapes(self._before, f"Undo {self.text()}")
        if self._settings is not None:
            document._apply_settings(self._settings[0])


class _UnitsCommand(_ContentCommand):
    """The document's length unit chosen (Edit > Units, the toolbar's Units): undo restores the
    one before."""

    def __init__(self, document: Document, old: str | None, new: str | None):
        super().__init__(document, f"Units: {new or 'unknown'}")
        self._old, self._new = old, new

    def redo(self):
        if self._current():
            self._document._apply_units(self._new)

    def undo(self):
        if self._current():
            self._document._apply_units(self._old)


class _SolidCommand(QUndoCommand):
    """A face edit of the solid (merge, split, a type): undo puts back the solid before, redo
    the edited one. Each applies only while the document still shows the solid it replaces (a
    new run of the part route, Reset or other files make the step obsolete)."""

    def __init__(self, document: Document, before: Any, after: Any, text: str):
        super().__init__(text)
        self._document, self._before, self._after = document, before, after
        self._pushed = False

    def redo(self):
        if self._pushed:
            self._swap(self._before, self._after, f"Redo {self.text()}")
        else:  # the push: the edit itself, which its policy reports
            self._document.set_solid(self._after)
        self._pushed = True

    def undo(self):
        self._swap(self._after, self._before, f"Undo {self.text()}")

    def _swap(self, shown: Any, new: Any, by: str) -> None:
        if self._document.solid is not shown:
            self.setObsolete(True)
            return
        self._document.set_solid(new)
        self._document.solid_restored.emit(by)


class _SettingsCommand(QUndoCommand):
    def __init__(self, document: Document, old: Settings, new: Settings, text: str):
        super().__init__(text)
        self._document, self._old, self._new = document, old, new

    def redo(self):
        self._document._apply_settings(self._new)

    def undo(self):
        self._document._apply_settings(self._old)


class Document(QObject):
    """What the window shows and saves. Signals fire in the GUI thread only."""

    content_changed = Signal()  # targets and/or patches replaced
    fitted_changed = Signal()
    offsets_changed = Signal()
    settings_changed = Signal(object, object)  # (old Settings, new Settings)
    points_changed = Signal()  # a point edit (crop, delete) or its undo / redo
    #: an undo / redo put back fitted shapes: (the fitted shape changed, the network changed)
    shapes_restored = Signal(bool, bool)
    selection_changed = Signal()
    units_changed = Signal()  # the document's length unit (replaced content sends it too)
    solid_changed = Signal()  # the solid of the part route (Solid mode) replaced or dropped
    #: an undo / redo of a face edit put a solid back: "Undo Merge regions 2, 5"
    solid_restored = Signal(str)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self.targets: list[Target] = []
        self.patches: list[GeometryArrays] = []
        self.patch_names: list[str] = []
        #: how many curves the opened cloud holds when it holds several (each fitted when it
        #: opened, among :attr:`patches`); 0 otherwise. One live fit holds one shape.
        self.several_curves = 0
        self.fitted: GeometryArrays | None = None
        #: what :attr:`fitted` is and how it was made (None with no fitted shape)
        self.fitted_account: FitAccount | None = None
        #: the fitted patch network (``nurbs_core.patches.network.PatchNetwork``) or None
        self.network: Any = None
        self.offsets = OffsetDisplay()
        self.settings = Settings()
        #: the length unit of the coordinates (one of ``nurbs_core.io.units.UNITS``), None while
        #: unknown: what every length shown is in and what .3dm / STEP exports declare (the
        #: coordinates are never scaled)
        self.units: str | None = None
        self.undo_stack = QUndoStack(self)
        #: bool (N,) over :meth:`target_points` (True: selected), or None: nothing selected
        self.selection: np.ndarray | None = None
        #: counts content replacements: point edits made before one cannot be undone after it
        self.content_generation = 0
        #: what a session keeps of the fit that made :attr:`network` (the window's patch
        #: controller answers); point edits keep it with the network they restore
        self.network_report_source: Callable[[], dict[str, Any] | None] = lambda: None
        #: the report of the network an undo / redo just restored
        self.restored_network_report: dict[str, Any] | None = None
        #: the loss plot's curves now (the window's loss plot answers): kept with each step
        self.loss_history_source: Callable[[], LossHistory | None] = lambda: None
        #: the status bar's run labels now (the window's answer): kept with each step
        self.run_texts_source: Callable[[], tuple[str, str, str] | None] = lambda: None
        #: the run labels of the shapes an undo / redo just restored
        self.restored_run_texts: tuple[str, str, str] | None = None
        #: the curves of the shapes an undo / redo just restored (None: an empty plot)
        self.restored_loss_history: LossHistory | None = None
        #: what put the shapes back: "Undo Fit", "Redo Crop to ..." (the step's text)
        self.restored_by = ""
        #: the solid of the part route (:class:`app.workers.part_worker.PartOutcome`: the
        #: OpenCASCADE shape, its report and triangles) or None; a run of the part route is no
        #: step of the undo history, a face edit of its solid is (:meth:`record_solid_edit`)
        self.solid: Any = None
        #: the switch to Patches mode waiting for its network fit (begin_fit_as_patches)
        self._pending_switch: _ShapesCommand | None = None

    # --- settings (undoable) -------------------------------------------------------------------
    def edit_settings(self, text: str, **changes: Any) -> bool:
        """Push an undoable edit of the fit's or the window's settings (see :func:`with_changes`);
        returns False when nothing changes."""
        return self._push(text, with_changes(self.settings, **changes))

    def edit_patches(self, text: str, **changes: Any) -> bool:
        """Push an undoable edit of the patch network's options (PatchOptions field names)."""
        patches = dataclasses.replace(self.settings.patches, **changes)
        return self._push(text, dataclasses.replace(self.settings, patches=patches))

    def _push(self, text: str, new: Settings) -> bool:
        if new == self.settings:
            return False
        self.undo_stack.push(_SettingsCommand(self, self.settings, new, text))
        return True

    def _apply_settings(self, new: Settings):
        old, self.settings = self.settings, new
        self.settings_changed.emit(old, new)

    # --- units (undoable) ---------------------------------------------------------------------
    def set_units(self, units: str | None) -> bool:
        """Choose the length unit of the coordinates as an undoable edit (None: unknown);
        returns False when it does not change. Nothing is scaled."""
        if units == self.units:
            return False
        self.undo_stack.push(_UnitsCommand(self, self.units, units))
        return True

    def _apply_units(self, units: str | None):
        self.units = units
        self.units_changed.emit()

    # --- fitted shapes (undoable) -------------------------------------------------------------
    def shape_state(self) -> ShapeState:
        """The fitted shapes now (what a fit's or Reset's step restores)."""
        return ShapeState(self.fitted, self.fitted_account, self.network, self.report_network(),
                          self.loss_history_source(), self.run_texts_source())

    def record_shapes(self, before: ShapeState, text: str, network_fit: bool = False) -> bool:
        """Push the change of the shapes since ``before`` (a fit has ended, Reset) as one
        undoable step; nothing when the shapes are the same ones. ``network_fit``: a patch
        network fit, which completes the switch to Patches mode made for it when that switch is
        still the newest step (one step then: Undo returns to one patch and the shapes before).
        Returns whether the history changed."""
        pending, self._pending_switch = (self._pending_switch, None) if network_fit else (
            None, self._pending_switch)
        after = self.shape_state()
        if after.same_shapes(before):
            return False
        stack = self.undo_stack
        if (pending is not None and stack.index() == stack.count()
                and stack.command(stack.index() - 1) is pending):
            pending.complete(after)
            return True
        self.undo_stack.push(_ShapesCommand(self, before, after, text))
        return True

    def begin_fit_as_patches(self, text: str = "Fit as patches") -> bool:
        """Switch to Patches mode to fit a network (the refusal of one patch, its poor fit, the
        "Fit as patches" button): one undoable step, which the network fit that follows
        completes (:meth:`record_shapes`). Returns False when the mode is Patches already."""
        new = with_changes(self.settings, fit_mode="patches")
        if new == self.settings:
            return False
        shapes = self.shape_state()
        command = _ShapesCommand(self, shapes, shapes, text, (self.settings, new))
        self.undo_stack.push(command)
        self._pending_switch = command
        return True

    def _apply_shapes(self, state: ShapeState, by: str = ""):
        fitted_changed = (state.fitted is not self.fitted
                          or state.fitted_account != self.fitted_account)
        network_changed = state.network is not self.network
        self.fitted, self.fitted_account = state.fitted, state.fitted_account
        self.network, self.restored_network_report = state.network, state.network_report
        self.restored_loss_history = state.loss_history
        self.restored_run_texts = state.run_texts
        self.restored_by = by
        self.shapes_restored.emit(fitted_changed, network_changed)
        if fitted_changed:
            self.fitted_changed.emit()

    # --- content ---------------------------------------------------------------------------------
    def replace_content(self, targets: list[Target], patches: list[Mapping[str, Any]],
                        patch_names: list[str], units: str | None = None):
        """Swap in freshly loaded files (all already validated) in ``units`` (the length unit
        they are in; None: unknown); drops the fit and offsets."""
        self.targets, self.patch_names = targets, patch_names
        self.units = units
        self.content_generation += 1
        self.selection = None
        self.patches = [from_mapping(p) for p in patches]
        self.fitted = self.fitted_account = None
        self.network = None
        self.solid = None
        self.offsets = OffsetDisplay()
        self.content_changed.emit()
        self.solid_changed.emit()
        self.fitted_changed.emit()
        self.offsets_changed.emit()
        self.selection_changed.emit()
        self.units_changed.emit()

    def set_fitted(self, geometry: Mapping[str, Any] | None, notify: bool = True,
                   account: FitAccount | None = None):
        """Replace the fitted shape. Live fit updates pass ``notify=False``: the controller
        already hands their display arrays to the view, so nothing needs re-tessellating.
        account: how the shape was made (a fit); None: what the shape itself says (its grid),
        made under the settings now (a shape from a session)."""
        self.fitted = None if geometry is None else from_mapping(geometry)
        if self.fitted is None:
            self.fitted_account = None
        else:
            self.fitted_account = account or FitAccount.of(
                self.fitted, grid_setting=grid_setting(self.settings.fit))
        if notify:
            self.fitted_changed.emit()

    def set_network(self, network: Any):
        """The patch network now shown (the newest of a live run, or None after Reset)."""
        self.network = network

    def set_solid(self, solid: Any) -> None:
        """The solid now shown (a PartOutcome with its solid), or None."""
        self.solid = solid
        self.solid_changed.emit()

    def record_solid_edit(self, before: Any, after: Any, text: str) -> None:
        """A face edit made ``after`` (a PartOutcome) of ``before``, the solid shown: shows it,
        as an undoable step named ``text``."""
        self.undo_stack.push(_SolidCommand(self, before, after, text))

    def set_offsets(self, offsets: OffsetDisplay):
        self.offsets = offsets
        self.offsets_changed.emit()

    def target_points(self) -> np.ndarray | None:
        """All visible targets stacked: (N, 3), or None when there is nothing to fit."""
        clouds = [t.points for t in self.targets if t.visible and len(t.points)]
        return np.concatenate(clouds, axis=0) if clouds else None

    # --- selection and point edits ---------------------------------------------------------------
    def set_selection(self, selection: np.ndarray | None) -> None:
        """Select points of the visible clouds: bool (N,) over :meth:`target_points` (an empty
        selection is None). Raises ValueError when the length does not match."""
        if selection is not None:
            selection = np.asarray(selection, bool)
            count = self.visible_point_count()
            if selection.shape != (count,):
                raise ValueError(f"a selection of {selection.shape} for {count} points")
            if not selection.any():
                selection = None
        if selection is None and self.selection is None:
            return
        self.selection = selection
        self.selection_changed.emit()

    def selected_count(self) -> int:
        return 0 if self.selection is None else int(np.count_nonzero(self.selection))

    def file_mesh(self) -> tuple[Any, str]:
        """The input file's own mesh for the route of what Start fits (a ScanMesh or None) and
        why a mesh file's mesh cannot serve (``choose_route``'s ``file_mesh`` and
        ``file_mesh_note``): those of the one visible cloud while it is fitted whole and as
        read (no selection, no points deleted); (None, "") otherwise."""
        visible = [t for t in self.targets if t.visible and len(t.points)]
        if len(visible) != 1 or self.selection is not None:
            return None, ""
        target = visible[0]
        if target.read_points is None or target.points is not target.read_points:
            return None, ""
        return target.mesh, target.mesh_note

    def ordered_points(self) -> tuple[np.ndarray, np.ndarray] | None:
        """What a fit that keeps every point in the file's order (a curve's:
        :func:`nurbs_core.io.cloud.keeps_every_point`) fits instead of the visible points, while
        they are fitted whole (no selection) and as read (no point deleted) and a file lists
        some twice: (the visible files' points as listed, stacked (K, 3), the row of them each
        visible point is (N,) int); None otherwise (the visible points are what it fits)."""
        visible = [t for t in self.targets if t.visible and len(t.points)]
        if self.selection is not None or all(t.file_order is None for t in visible):
            return None
        if any(t.read_points is None or t.points is not t.read_points for t in visible):
            return None
        listed, rows, start = [], [], 0
        for target in visible:
            order = target.file_order
            points = target.points if order is None else order.points
            listed.append(points)
            rows.append(start + (np.arange(len(points)) if order is None else order.rows))
            start += len(points)
        return np.concatenate(listed, axis=0), np.concatenate(rows)

    def fit_points(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """What Start fits: (the selected points (M, 3), the selection (N,)) while points are
        selected, else (all visible points (N, 3) or None, None)."""
        points = self.target_points()
        if points is None or self.selection is None:
            return points, None
        return points[self.selection], self.selection.copy()

    def keep_points(self, keep: np.ndarray, text: str) -> int:
        """Keep only the visible points where ``keep`` (bool (N,) over :meth:`target_points`) is
        True, as one undoable edit (hidden clouds are left alone); the selection is cleared.
        Returns how many points were removed (0: no edit pushed)."""
        keep = np.asarray(keep, bool)
        points = self.target_points()
        if points is None or keep.shape != (len(points),):
            raise ValueError("keep must have one entry per visible point")
        removed = int(len(keep) - np.count_nonzero(keep))
        if removed == 0:
            return 0
        edited, start = [], 0
        for target in self.targets:
            if target.visible and len(target.points):
                part = keep[start:start + len(target.points)]
                start += len(target.points)
                edited.append(target.points[part])
            else:
                edited.append(target.points)
        before = self._points_state()
        after = dataclasses.replace(before, points=tuple(edited), selection=None)
        self.undo_stack.push(_PointsCommand(self, before, after, text))
        return removed

    def report_network(self) -> dict[str, Any] | None:
        return self.network_report_source() if self.network is not None else None

    def _points_state(self) -> PointsState:
        return PointsState(tuple(t.points for t in self.targets),
                           None if self.selection is None else self.selection.copy(),
                           tuple(t.visible for t in self.targets), self.shape_state())

    def _apply_points(self, state: PointsState, by: str = ""):
        for target, points in zip(self.targets, state.points, strict=True):
            target.points = points
        visible = tuple(t.visible for t in self.targets)
        self.selection = state.selection if visible == state.visible else None
        shapes = state.shapes
        network_changed = shapes.network is not self.network
        self.fitted, self.fitted_account = shapes.fitted, shapes.fitted_account
        self.network, self.restored_network_report = shapes.network, shapes.network_report
        self.restored_loss_history = shapes.loss_history
        self.restored_run_texts = shapes.run_texts
        self.restored_by = by
        self.points_changed.emit()
        self.selection_changed.emit()
        self.shapes_restored.emit(True, network_changed)
        self.fitted_changed.emit()  # measured again against the points now shown

    def visible_point_count(self) -> int:
        """How many points :meth:`target_points` stacks (without stacking them)."""
        return sum(len(t.points) for t in self.targets if t.visible)

    def all_geometry(self) -> list[GeometryArrays]:
        """Fitted geometry, loaded patches and offsets: what Export writes."""
        items = [self.fitted] if self.fitted is not None else []
        return items + list(self.patches) + list(self.offsets.surfaces)

    # --- sessions (the file format: app.session_file) -------------------------------------
    def apply_session(self, session: dict[str, Any]):
        """Replace the document with a session read by :func:`app.session_file.read_session`
        (its network is shown by the window's patch controller, which hands it to
        :meth:`set_network`)."""
        self.replace_content(session["targets"], session["patches"], session["names"],
                             session.get("units"))
        self.undo_stack.clear()
        self._apply_settings(session["settings"])
        self.set_fitted(session["fitted"])
        if session.get("solid") is not None:
            self.set_solid(session["solid"])

