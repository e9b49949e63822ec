"""The document: targets (point clouds), the fitted geometry, loaded patches, offsets, settings.

Pure data plus Qt signals; no torch, no VTK. Settings edits go through a ``QUndoStack`` so every
edit can be undone and redone; loading files replaces the content and is not an undoable edit.
Geometry is held as the numpy dicts of ``NurbsCurve.numpy()`` / ``NurbsSurface.numpy()``.
"""

from __future__ import annotations

import dataclasses
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QUndoCommand, QUndoStack

from nurbs_core.patches.defaults import SEAM_WEIGHT
from nurbs_core.patches.defaults import STIFFNESS as PATCH_STIFFNESS

SESSION_FORMAT = "nurbs-studio-session-v1"

#: Loss terms the settings panel offers, in display order (names of ``nurbs_core.losses``).
#: l1 / l2 / mse pair the i-th sample with the i-th point: meaningful only for ordered targets.
#: Kept equal to ``nurbs_core.losses.TERMS`` (a test checks it).
LOSS_TERMS = ("p2s", "chamfer", "hausdorff", "laplacian", "fairing", "length", "l1", "l2",
              "mse")
OPTIMIZERS = ("adam", "sgd", "momentum", "adagrad", "lbfgs")
INITIALIZATIONS = ("pca", "least_squares", "random")
#: The engine's solvers and parameterisations of unordered surface clouds (FitConfig.solver,
#: FitConfig.parameterization) in display order, with their labels (a test checks they agree).
SOLVERS = (("auto", "auto"), ("least_squares", "least squares"), ("gradient", "gradient"))
PARAMETERIZATIONS = (("auto", "auto"), ("mesh", "mesh"), ("plane", "plane"))
#: How Start fits the cloud: one NURBS surface (or curve), or a network of patches over a quad
#: layout (closed objects: ``nurbs_core.patches``).
FIT_MODES = (("single", "Single patch"), ("patches", "Patches"))
TOLERANCE_HINT = ("Tolerance: a positive distance in the cloud's units (e.g. 0.01), or empty / "
                  "\"auto\" to derive it from the cloud's noise")

_TERM = re.compile(r"^\s*(?:(?P<weight>[0-9.eE+-]+)\s*\*\s*)?(?P<name>[a-z_0-9]+)\s*$")


#: A surface fit wants several points per control point; fewer leaves the net free to fold.
POINTS_PER_CONTROL_POINT = 8


def control_grid_for(point_count: int, settings: FitSettings) -> tuple[int, int] | None:
    """A smaller (n_u, n_v) when the cloud is too small for the settings' control grid, else None.

    Each direction gets at most sqrt(points / POINTS_PER_CONTROL_POINT) control points, never
    fewer than degree + 1 (the grid is only ever reduced)."""
    if settings.kind != "surface":
        return None
    limit = int((point_count / POINTS_PER_CONTROL_POINT) ** 0.5)
    n_u = min(settings.control_points_u, max(settings.degree_u + 1, limit))
    n_v = min(settings.control_points_v, max(settings.degree_v + 1, limit))
    if (n_u, n_v) == (settings.control_points_u, settings.control_points_v):
        return None
    return n_u, n_v


def parse_loss(text: str) -> tuple[tuple[str, float], ...]:
    """``"chamfer+0.1*laplacian"`` -> ``(("chamfer", 1.0), ("laplacian", 0.1))``."""
    terms = []
    for part in text.replace(" ", "").split("+"):
        match = _TERM.match(part)
        if not match:
            raise ValueError(f"cannot read loss term {part!r} in {text!r} "
                             "(expected e.g. 'chamfer+0.1*laplacian')")
        terms.append((match["name"], float(match["weight"] or 1.0)))
    return tuple(terms)


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


def format_loss(terms) -> str:
    """Inverse of :func:`parse_loss`; terms with weight 0 are left out."""
    # positional notation: the engine's parser splits on "+", so "1e+06" must never appear
    parts = [name if weight == 1.0 else f"{np.format_float_positional(weight, trim='-')}*{name}"
             for name, weight in terms if weight]
    if not parts:
        raise ValueError("the loss needs at least one term with a non-zero weight")
    return "+".join(parts)


@dataclass(frozen=True)
class FitSettings:
    """Everything the user can edit. Immutable: edits make a new object (undo keeps the old)."""

    kind: str = "surface"
    degree_u: int = 3
    degree_v: int = 3
    control_points_u: int = 12
    control_points_v: int = 12
    #: ``nurbs_core.fitting.DEFAULT_LOSS`` (a test checks they agree)
    loss: tuple[tuple[str, float], ...] = (("p2s", 1.0), ("chamfer", 0.001))
    optimizer: str = "adam"
    learning_rate: float = 0.01
    iterations: int = 500
    free_knots: bool = False
    free_weights: bool = False
    pin_boundary: bool = False
    init: str = "pca"
    samples_u: int = 64
    samples_v: int = 64
    #: the least-squares core (``nurbs_core.fitting.FitConfig``): fairing weight, two-sided
    #: distance tolerance (None: from the cloud's noise), how far the control grid may grow,
    #: the solver, the parameterisation of unordered clouds, and forcing one patch
    stiffness: float = 1e-3
    tolerance: float | None = None
    max_control_points: int = 40
    solver: str = "auto"
    parameterization: str = "auto"
    single_patch: bool = False
    #: Custom knot vectors (full, clamped) or None for the clamped uniform preset.
    knots_u: tuple[float, ...] | None = None
    knots_v: tuple[float, ...] | None = None
    offset_distance: float = 0.1
    constrain_shared_edges: bool = True
    show_offsets: bool = False
    #: "single" or "patches" (:data:`FIT_MODES`)
    fit_mode: str = "single"
    #: the patch network fit (``nurbs_core.patches.pipeline.PatchOptions``): target patch count
    #: and control points per patch side (None: automatic), fairing stiffness and seam weight
    #: (the engine's defaults)
    patch_count: int | None = None
    patch_size: int | None = None
    patch_stiffness: float = PATCH_STIFFNESS
    seam_weight: float = SEAM_WEIGHT

    @property
    def loss_text(self) -> str:
        return format_loss(self.loss)

    def structure(self) -> tuple:
        """What fixes the shape of the control net (a change needs a resampled start)."""
        if self.kind == "curve":
            return (self.kind, self.degree_u, self.control_points_u, self.knots_u)
        return (self.kind, self.degree_u, self.degree_v, self.control_points_u,
                self.control_points_v, self.knots_u, self.knots_v)

    def fit_fields(self) -> dict[str, Any]:
        """Keyword arguments for ``nurbs_core.fitting.FitConfig`` (only fields it declares)."""
        from nurbs_core.fitting import FitConfig  # lazy: keeps this module importable without torch

        wanted = {"kind": self.kind, "degree_u": self.degree_u, "degree_v": self.degree_v,
                  "control_points_u": self.control_points_u,
                  "control_points_v": self.control_points_v, "loss": self.loss_text,
                  "optimizer": self.optimizer, "learning_rate": self.learning_rate,
                  "iterations": self.iterations, "free_knots": self.free_knots,
                  "free_weights": self.free_weights, "pin_boundary": self.pin_boundary,
                  "init": self.init, "samples_u": self.samples_u, "samples_v": self.samples_v,
                  "stiffness": self.stiffness, "tolerance": self.tolerance,
                  "max_control_points": self.max_control_points, "solver": self.solver,
                  "parameterization": self.parameterization, "single_patch": self.single_patch}
        declared = {f.name for f in dataclasses.fields(FitConfig)}
        return {key: value for key, value in wanted.items() if key in declared}

    def patch_options(self):
        """The engine's ``PatchOptions`` for these settings (not validated here)."""
        from nurbs_core.patches.pipeline import PatchOptions  # lazy: no torch at import

        return PatchOptions(patches="auto" if self.patch_count is None else self.patch_count,
                            size=self.patch_size, stiffness=self.patch_stiffness,
                            seam_weight=self.seam_weight)

    def to_json(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        data["loss"] = self.loss_text
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> FitSettings:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown settings in session: {', '.join(unknown)}")
        values = dict(data)
        if "loss" in values:
            values["loss"] = parse_loss(values["loss"])
        for name in ("knots_u", "knots_v"):
            if values.get(name) is not None:
                values[name] = tuple(float(k) for k in values[name])
        return cls(**values)


#: The settings of the patch network fit (a change restarts a running patch fit, not the
#: single-patch one), and the mode switch.
PATCH_FIELDS = frozenset({"patch_count", "patch_size", "patch_stiffness", "seam_weight"})
MODE_FIELDS = frozenset({"fit_mode"})


def with_changes(settings: FitSettings, **changes) -> FitSettings:
    """``dataclasses.replace`` that also drops custom knots a degree/grid change invalidates."""
    new = dataclasses.replace(settings, **changes)
    counts = {"knots_u": new.control_points_u + new.degree_u + 1,
              "knots_v": new.control_points_v + new.degree_v + 1}
    drop = {name: None for name, count in counts.items()
            if getattr(new, name) is not None and len(getattr(new, name)) != count}
    return dataclasses.replace(new, **drop) if drop else new


@dataclass
class Target:
    """A point cloud to fit: points (N, 3) float64."""

    name: str
    points: np.ndarray
    path: str = ""
    visible: bool = True


@dataclass
class OffsetDisplay:
    surfaces: list[dict[str, Any]] = field(default_factory=list)
    max_gap: float = 0.0
    shared_edges: int = 0


class _SettingsCommand(QUndoCommand):
    def __init__(self, document: Document, old: FitSettings, new: FitSettings, text: str):
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
    settings_changed = Signal(object, object)  # (old FitSettings, new FitSettings)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self.targets: list[Target] = []
        self.patches: list[dict[str, Any]] = []
        self.patch_names: list[str] = []
        self.fitted: dict[str, Any] | None = None
        #: the fitted patch network (``nurbs_core.patches.network.PatchNetwork``) or None
        self.network: Any = None
        self.offsets = OffsetDisplay()
        self.settings = FitSettings()
        self.undo_stack = QUndoStack(self)

    # --- settings (undoable) -------------------------------------------------------------------
    def edit_settings(self, text: str, **changes) -> bool:
        """Push an undoable settings edit; returns False when nothing changes."""
        new = with_changes(self.settings, **changes)
        if new == self.settings:
            return False
        self.undo_stack.push(_SettingsCommand(self, self.settings, new, text))
        return True

    def _apply_settings(self, new: FitSettings):
        old, self.settings = self.settings, new
        self.settings_changed.emit(old, new)

    # --- content ---------------------------------------------------------------------------------
    def replace_content(self, targets: list[Target], patches: list[dict[str, Any]],
                        patch_names: list[str]):
        """Swap in freshly loaded files (all already validated); drops the fit and offsets."""
        self.targets, self.patches, self.patch_names = targets, patches, patch_names
        self.fitted = None
        self.network = None
        self.offsets = OffsetDisplay()
        self.content_changed.emit()
        self.fitted_changed.emit()
        self.offsets_changed.emit()

    def set_fitted(self, geometry: dict[str, Any] | None, notify: bool = True):
        """Replace the fitted shape. Live fit updates pass ``notify=False``: the controller
        already hands their display arrays to the view, so nothing needs re-tessellating."""
        self.fitted = geometry
        if notify:
            self.fitted_changed.emit()

    def set_network(self, network: Any):
        """The patch network now shown (the newest of a live run, or None after Reset)."""
        self.network = network

    def set_offsets(self, offsets: OffsetDisplay):
        self.offsets = offsets
        self.offsets_changed.emit()

    def target_points(self) -> np.ndarray | None:
        """All visible targets stacked: (N, 3), or None when there is nothing to fit."""
        clouds = [t.points for t in self.targets if t.visible and len(t.points)]
        return np.concatenate(clouds, axis=0) if clouds else None

    def all_geometry(self) -> list[dict[str, Any]]:
        """Fitted geometry, loaded patches and offsets: what Export writes."""
        items = [self.fitted] if self.fitted is not None else []
        return items + list(self.patches) + list(self.offsets.surfaces)

    # --- sessions --------------------------------------------------------------------------------
    def to_session(self) -> dict[str, Any]:
        return {
            "format": SESSION_FORMAT,
            "settings": self.settings.to_json(),
            "targets": [{"name": t.name, "path": t.path, "visible": t.visible,
                         "points": t.points.tolist()} for t in self.targets],
            "patches": [{"name": name, "geometry": _geometry_to_json(g)}
                        for name, g in zip(self.patch_names, self.patches, strict=True)],
            "fitted": None if self.fitted is None else _geometry_to_json(self.fitted),
        }

    def save_session(self, path: str | Path):
        """Write the session atomically: ``path`` is replaced only by a complete file (a failed
        write raises and leaves an existing file as it was)."""
        from nurbs_core.io.atomic import atomic_write

        text = json.dumps(self.to_session())  # before touching the disk: a failure writes nothing
        with atomic_write(path, "w") as handle:
            handle.write(text)

    def load_session(self, path: str | Path):
        """Read a session file and apply it; raises ValueError naming the problem (document
        untouched)."""
        self.apply_session(self.read_session(path))

    @staticmethod
    def read_session(path: str | Path) -> dict[str, Any]:
        """Parse and check a session file without touching any document; raises ValueError."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path}: not a readable session file ({exc})") from None
        if not isinstance(data, dict) or data.get("format") != SESSION_FORMAT:
            raise ValueError(f"{path}: not a NURBS Studio session (expected format "
                             f"{SESSION_FORMAT!r})")
        try:
            settings = FitSettings.from_json(data.get("settings", {}))
            targets = []
            for item in data.get("targets", []):
                points = np.asarray(item["points"], dtype=np.float64).reshape(-1, 3)
                targets.append(Target(item["name"], points, item.get("path", ""),
                                      bool(item.get("visible", True))))
            patches = [_geometry_from_json(p["geometry"]) for p in data.get("patches", [])]
            names = [p["name"] for p in data.get("patches", [])]
            fitted = data.get("fitted")
            fitted = None if fitted is None else _geometry_from_json(fitted)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: damaged session ({exc})") from None
        return {"settings": settings, "targets": targets, "patches": patches, "names": names,
                "fitted": fitted}

    def apply_session(self, session: dict[str, Any]):
        """Replace the document with a session from :meth:`read_session`."""
        self.replace_content(session["targets"], session["patches"], session["names"])
        self.undo_stack.clear()
        self._apply_settings(session["settings"])
        self.set_fitted(session["fitted"])


def _geometry_to_json(geometry: dict[str, Any]) -> dict[str, Any]:
    return {key: value.tolist() if isinstance(value, np.ndarray) else value
            for key, value in geometry.items()}


def _geometry_from_json(data: dict[str, Any]) -> dict[str, Any]:
    kind = data.get("kind")
    if kind not in ("curve", "surface"):
        raise ValueError(f"unknown geometry kind {kind!r}")
    return {key: np.asarray(value, dtype=np.float64) if isinstance(value, list) else value
            for key, value in data.items()}
