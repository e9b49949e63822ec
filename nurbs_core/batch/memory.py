"""How many local workers the machine's memory holds: ``--jobs N`` is capped so that N workers,
each fitting the batch's largest input, fit in the memory available now.

A worker's peak is estimated as ``WORKER_BASE + FIT_BASE + BYTES_PER_POINT x points`` of the
largest input. The constants were measured with nurbs-fit's default settings: a fresh process
that loads what a Dask worker loads (``distributed``, then ``worker.prepare_worker``: torch and
the engine) and fits one saddle cloud through ``worker.fit_item``, its peak read from
``ru_maxrss`` (session 56): 245 MB loaded; 324, 445, 543 and 824 MB after fitting 10,000,
100,000, 300,000 and 1,000,000 points (about 500 bytes a point between 10,000 and 1,000,000, and
a fixed 80-200 MB for the fit's own structures). The constants lie above every measured point.

An input's point count is estimated from its size on disk before it is read: an HDF5 item's
from its dataset's shape; a compressed format (``COMPRESSED_SUFFIXES``) as COMPRESSED_RATIO times
its size of float32 points (the upper end of real point data's 1.2-8x); any other file as
float32 x, y, z (FILE_BYTES_PER_POINT), the densest uncompressed layout, so text and float64
files are over-estimated, never under.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from nurbs_core.batch.inputs import Item

MIB = 2**20
#: A worker process with the engine loaded (torch, nurbs_core, distributed): 245 MB measured.
WORKER_BASE = 250 * MIB
#: A fit's fixed cost above the loaded process (80-200 MB measured from 10,000 to 300,000 points).
FIT_BASE = 200 * MIB
#: A fit's cost per point of its input (about 500 bytes measured between 10,000 and 1,000,000).
BYTES_PER_POINT = 600
#: The fewest bytes an uncompressed file spends on a point: float32 x, y, z.
FILE_BYTES_PER_POINT = 12
#: Point formats that may be compressed, and how many times their size they may inflate to.
COMPRESSED_SUFFIXES = (".npz", ".laz", ".e57", ".pcd")
COMPRESSED_RATIO = 8


def available_memory() -> int | None:
    """The bytes of memory available to new processes now (Linux: MemAvailable of
    /proc/meminfo, which counts reclaimable caches; else the free physical pages), None when
    the system does not say."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None


def _hdf5_cloud_points(path: str) -> int:
    """The points of each cloud of an HDF5 input (its ``points`` dataset's second axis)."""
    import h5py

    from nurbs_core.batch.inputs import HDF5_DATASET

    with h5py.File(path, "r") as handle:
        return int(handle[HDF5_DATASET].shape[1])


def estimated_points(item: Item, hdf5_points: dict[str, int] | None = None) -> int:
    """The points ``item`` is estimated to hold, from its size on disk (see the module
    docstring); 0 when it cannot be told (a missing file fails on its own). ``hdf5_points``:
    a cache of the points per cloud of the HDF5 files already looked at."""
    try:
        if item.index is not None:
            cache = {} if hdf5_points is None else hdf5_points
            if item.path not in cache:
                cache[item.path] = _hdf5_cloud_points(item.path)
            return cache[item.path]
        size = os.path.getsize(item.path)
    except Exception:  # noqa: BLE001 - unreadable: the fit reports it, it holds no memory
        return 0
    ratio = COMPRESSED_RATIO if os.path.splitext(item.path)[1].lower() in COMPRESSED_SUFFIXES \
        else 1
    return size * ratio // FILE_BYTES_PER_POINT


def worker_peak(points: int) -> int:
    """The estimated peak bytes of a worker fitting an input of ``points`` points."""
    return WORKER_BASE + FIT_BASE + BYTES_PER_POINT * max(0, int(points))


def workers_in_memory(items: list[Item]) -> tuple[int | None, int, int | None]:
    """How many workers fitting ``items`` fit in the memory available now (None: the system
    does not say), each one's estimated peak (for the largest input) and the memory available."""
    cache: dict[str, int] = {}
    largest = max((estimated_points(item, cache) for item in items), default=0)
    peak = worker_peak(largest)
    available = available_memory()
    if available is None:
        return None, peak, None
    return max(1, available // peak), peak, available
