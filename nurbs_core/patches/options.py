"""The settings of a patch-network fit (:class:`PatchOptions`), free of numpy and torch: the
command line, the Python API (:func:`nurbs_core.patches.pipeline.fit_patches`) and the app's
document all hold this one type."""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from nurbs_core.patches.defaults import SEAM_WEIGHT, STIFFNESS

#: The most patches a network may ask for (memory grows with the count: 100,000 reached 8.6 GB),
#: and the fewest cloud points each patch needs (:func:`check_patch_count`).
MAX_PATCHES = 2000
POINTS_PER_PATCH = 4
#: A network's memory (:func:`network_bytes`): a base, a share per control point (the fit's
#: sample grids hold 9 samples per control point) and a dense block per patch over its
#: interior, (s - 2)^4 entries (the condensed solve). Fitted to nurbs-fit on a 10,000-point
#: sphere: 2,005 patches of 4 x 4 (18,000 control points) peaked at 0.81 GB, 1,963 of 6 x 6
#: (49,000) at 1.87 GB, 205 of 16 x 16 (46,000) at 1.68 GB, 29 of 40 x 40 (44,000) at 2.52 GB;
#: 2,005 of 40 x 40 reached 23.7 GB. The estimate was never below the measured peak (+0.01 to
#: +0.22 GB; 40 of 30 x 30, not used to fit it: 1.74 estimated, 1.52 GB measured), so
#: MAX_NETWORK_BYTES keeps a small cloud's network under 2 GB (docs/fitting.md, "Bounds").
NETWORK_BASE_BYTES = 200e6
BYTES_PER_CONTROL_POINT = 34e3
BYTES_PER_BLOCK_ENTRY = 16
MAX_NETWORK_BYTES = 1.9e9


def network_control_points(patches: int, size: int) -> int:
    """The control points a closed network of ``patches`` quads with ``size`` x ``size`` per
    patch shares: F (s - 1)^2 + 2 (corners and sides are shared; an open network has a few
    more along its border)."""
    return patches * (size - 1) ** 2 + 2


def network_bytes(patches: int, size: int, control_points: int | None = None) -> float:
    """About the memory a network fit of ``patches`` patches of ``size`` x ``size`` control
    points takes (``control_points`` in all; by default :func:`network_control_points`)."""
    if control_points is None:
        control_points = network_control_points(patches, size)
    return (NETWORK_BASE_BYTES + BYTES_PER_CONTROL_POINT * control_points
            + BYTES_PER_BLOCK_ENTRY * patches * max(0, size - 2) ** 4)


def check_network_memory(patches: int, size: int, control_points: int | None = None) -> None:
    """ValueError when a network of ``patches`` patches of ``size`` per side would take more
    than :data:`MAX_NETWORK_BYTES` (:func:`network_bytes`); the message says what fits."""
    needed = network_bytes(patches, size, control_points)
    if needed <= MAX_NETWORK_BYTES:
        return
    sizes = [s for s in range(4, size) if network_bytes(patches, s) <= MAX_NETWORK_BYTES]
    fewer = next((n for n in range(patches - 1, 3, -1) if network_bytes(n, size) <= MAX_NETWORK_BYTES),
                 None)
    choices = (([f"at most {fewer} patches of that size"] if fewer is not None else [])
               + ([f"a size of at most {sizes[-1]}"] if sizes else []))
    advice = ", ".join(choices + ["or no size (it grows by itself)"])
    raise ValueError(f"size: {patches} patches of {size} x {size} control points would take about "
                     f"{needed / 1e9:.1f} GB, more than the {MAX_NETWORK_BYTES / 1e9:.2f} GB a "
                     f"network fit may (its memory grows with the control points); ask for "
                     f"{advice}")


def check_patch_count(patches: int | str, points: int) -> None:
    """ValueError when an explicit patch count asks for more patches than the cloud's
    ``points`` can support (``POINTS_PER_PATCH`` each)."""
    if patches != "auto" and int(patches) * POINTS_PER_PATCH > points:
        raise ValueError(f"patches: {patches} patches need at least "
                         f"{int(patches) * POINTS_PER_PATCH} points ({POINTS_PER_PATCH} each); "
                         f"the cloud has {points}: ask for at most "
                         f"{max(4, points // POINTS_PER_PATCH)} or 'auto'")


def _number(value: object) -> bool:
    """Whether ``value`` is a real number (not text, not true/false)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


@dataclass(frozen=True)
class PatchOptions:
    """Settings of a network fit. patches: "auto" or a target patch count (>= 4); size: control
    points per patch side (None: grow while Cp falls); degree: of every patch; stiffness:
    fairing weight relative to the data term; seam_weight: of tangent continuity (both raised
    with the noise over a scan noisier than 0.5% of its diagonal, whoever set them:
    :func:`nurbs_core.patches.defaults.noise_weights`); tolerance: RMS
    distance to reach (cloud units, None: automatic); max_size: largest control grid per side;
    max_hole: the widest opening of the scan sealed by a smooth cap (cloud units; None: 10% of
    the diagonal; 0: none); creases: find the scan's creases and lay patch boundaries on them,
    left G0 (:mod:`nurbs_core.patches.creases`). Immutable: ``dataclasses.replace`` makes an
    edited copy."""

    patches: int | str = "auto"
    size: int | None = None
    degree: int = 3
    stiffness: float = STIFFNESS
    seam_weight: float = SEAM_WEIGHT
    tolerance: float | None = None
    max_size: int = 16
    max_hole: float | None = None
    creases: bool = True

    def validate(self) -> None:
        """Raise ValueError naming the first bad setting."""
        if self.patches != "auto" and (isinstance(self.patches, bool)
                                       or not isinstance(self.patches, numbers.Integral)
                                       or self.patches < 4):
            raise ValueError(f"patches must be 'auto' or an integer of at least 4, got "
                             f"{self.patches!r}")
        if isinstance(self.patches, numbers.Integral) and self.patches > MAX_PATCHES:
            raise ValueError(f"patches: at most {MAX_PATCHES} patches, got {self.patches} (each "
                             "patch holds a grid of control points; a finer network needs a "
                             "finer control grid per patch: size)")
        for name in ("degree", "max_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise ValueError(f"{name} must be an integer, got {value!r}")
        if self.degree != 3:
            raise ValueError(f"patch networks are bicubic for now (degree 3), got {self.degree}")
        if self.size is not None and not (isinstance(self.size, numbers.Integral)
                                          and self.degree < self.size <= 40):
            raise ValueError(f"size must be an integer from {self.degree + 1} to 40, got "
                             f"{self.size!r}")
        if isinstance(self.patches, numbers.Integral) and self.size is not None:
            check_network_memory(self.patches, self.size)
        if not self.degree < self.max_size <= 40:
            raise ValueError(f"max_size must be an integer from {self.degree + 1} to 40, got "
                             f"{self.max_size!r}")
        for name in ("stiffness", "seam_weight"):
            value = getattr(self, name)
            if not (_number(value) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite non-negative number, got {value!r}")
        if self.tolerance is not None and not (_number(self.tolerance)
                                               and math.isfinite(self.tolerance)
                                               and self.tolerance > 0):
            raise ValueError(f"tolerance must be a positive number, got {self.tolerance!r}")
        if not isinstance(self.creases, bool):
            raise ValueError(f"creases must be true or false, got {self.creases!r}")
        if self.max_hole is not None and not (_number(self.max_hole)
                                              and math.isfinite(self.max_hole)
                                              and self.max_hole >= 0):
            raise ValueError(f"max_hole must be a finite non-negative length, got "
                             f"{self.max_hole!r}")

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PatchOptions:
        """Inverse of :meth:`to_json`; raises ValueError for fields PatchOptions does not have."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown patch settings: {', '.join(unknown)}")
        return cls(**data)
