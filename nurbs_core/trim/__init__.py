"""Trimmed patches of open sheets: a surface over a rectangle around the scan's outline, trimmed
by fair B-spline loops that follow the outline (value types in :mod:`nurbs_core.trim.value`, the
fit in :mod:`nurbs_core.trim.fit`)."""

from __future__ import annotations

from nurbs_core.trim.value import TrimLoop, TrimmedSurface

__all__ = ["TrimLoop", "TrimmedSurface"]
