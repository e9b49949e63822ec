"""What a resume (``--skip-existing``) may skip: a result that is whole and of the kind the run
writes, and never an earlier run's result taken for an input."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from nurbs_core.jobs import FitJob

#: The kinds of result a batch writes (:func:`result_kind`).
CURVE, SURFACE, NETWORK = "curve", "surface", "network"
#: The summary columns holding each result's size in bytes and its ``--offset`` companion's
#: (a resume compares them), in the order of an item's outputs.
OUTPUT_BYTES, OFFSET_BYTES = "output_bytes", "offset_bytes"
SIZE_COLUMNS = (OUTPUT_BYTES, OFFSET_BYTES)


def result_kind(job: FitJob) -> str:
    """What each result of ``job`` holds: curves (``--curve``), a patch network (``--patches``),
    else a surface (the automatic route may also make a network, a trimmed face or a solid)."""
    if job.curve:
        return CURVE
    return NETWORK if job.patches is not None else SURFACE


def _head(path: str, size: int = 4096) -> str:
    with open(path, encoding="utf-8", errors="replace") as handle:
        return handle.read(size)


def _readable_as(path: str, kind: str) -> bool:
    """Whether ``path`` reads back whole as a result of ``kind`` (point and mesh formats: a
    non-empty cloud)."""
    from nurbs_core.io.dispatch import load_any
    from nurbs_core.io.points import suffix_of

    if suffix_of(path) == ".json" and "nurbs-studio-network" in _head(path, 400):
        from nurbs_core.io.network_io import read_network

        return kind != CURVE and read_network(path).patch_count > 0
    if suffix_of(path) == ".json" and kind == NETWORK:
        return False  # a network's .json is our network format
    content = load_any(path)
    if not isinstance(content, list):
        return len(content.points) > 0
    from nurbs_core.geometry import NurbsCurve

    curves = [isinstance(shape, NurbsCurve) for shape in content]
    if not curves:
        return False
    return all(curves) if kind == CURVE else not all(curves)


def has_recorded_size(size: int, recorded_bytes: object) -> bool:
    """Whether a file of ``size`` bytes has the size its summary row recorded
    (``recorded_bytes``, the :data:`OUTPUT_BYTES` cell: blank when the row recorded none, which
    any size matches; a cell that is not a whole number matches none)."""
    if recorded_bytes in (None, ""):
        return True
    try:
        return int(str(recorded_bytes)) == size
    except ValueError:
        return False


def is_complete(path: str, kind: str, recorded_bytes: object = None) -> bool:
    """Whether an earlier result can be skipped: it reads back whole as a ``kind`` result
    (an empty file, one a killed run cut short, a curve where a surface is due: fitted again)
    and, when its summary row recorded its size (``recorded_bytes``), has that size."""
    try:
        size = os.path.getsize(path)
        if size == 0 or not has_recorded_size(size, recorded_bytes):
            return False
        return _readable_as(path, kind)
    except Exception:  # noqa: BLE001 - unreadable for any reason: not a finished result
        return False


def earlier_outputs(rows: dict[str, dict]) -> tuple[Path, ...]:
    """The files an earlier run wrote (its summary's finished rows: each result and its
    ``--offset`` companion): a folder's expansion leaves them out, so that a rerun into an input
    folder does not fit its own results. A result no longer of the size its row recorded was
    replaced since (a cloud of the user's): it stays an input."""
    from nurbs_core.jobs.checks import offset_path

    paths: list[Path] = []
    for row in rows.values():
        output = Path(str(row["output"]))
        try:
            if not has_recorded_size(output.stat().st_size, row.get(OUTPUT_BYTES)):
                continue
        except OSError:
            continue
        paths += [output, offset_path(output)]
    return tuple(paths)
