"""The inputs of a batch: files, folders, globs and HDF5 datasets expanded into items, each with
its result's name. An input that cannot be expanded (missing, an empty folder, a glob that
matches nothing, an unreadable HDF5 file) becomes an item with its error, never an exception."""

from __future__ import annotations

import glob
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

#: Suffixes read as HDF5 datasets of clouds (SplineDataset layout: ``points`` (N, n, 3)).
HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf")
#: The dataset of an HDF5 file that holds the clouds.
HDF5_DATASET = "points"
#: The most clouds a batch takes from one HDF5 file (each is an item of the batch, named and
#: tracked before the first fit: a million take about 0.6 GB).
MAX_HDF5_CLOUDS = 1_000_000
BATCH_EXTRA_HINT = "pip install 'nurbs-studio[batch]' (or: pip install h5py \"dask[distributed]\")"


@dataclass
class Item:
    """One input of a batch: ``path`` (a cloud file, or an HDF5 file with ``index``), the name its
    results are given, and ``error`` when it cannot be fitted at all."""

    label: str
    path: str  # as given (Dask executors make it absolute)
    name: str
    index: int | None = None
    error: str | None = None
    outputs: list[str] = field(default_factory=list)

    def plain(self) -> dict:
        """What a worker receives: paths and numbers only."""
        return {"input": self.label, "path": self.path, "index": self.index,
                "outputs": list(self.outputs)}


def _is_glob(text: str) -> bool:
    return any(c in text for c in "*?[")


def _cloud_suffixes() -> tuple[str, ...]:
    from nurbs_core.io.points import POINT_CLOUD_SUFFIXES

    return (*POINT_CLOUD_SUFFIXES, *HDF5_SUFFIXES)


def hdf5_count(path: str) -> int:
    """The number of clouds in an HDF5 file (ValueError unless ``points`` is (N, n, 3))."""
    try:
        import h5py
    except ImportError:
        raise ImportError(f"{path}: reading HDF5 files needs h5py: {BATCH_EXTRA_HINT}") from None
    from nurbs_core.io.limits import check_dataset_size

    with h5py.File(path, "r") as handle:
        if HDF5_DATASET not in handle:
            raise ValueError(f"{path}: no '{HDF5_DATASET}' dataset (expected the SplineDataset "
                             f"layout, '{HDF5_DATASET}' of shape (N, n, 3))")
        shape = handle[HDF5_DATASET].shape
    if len(shape) != 3 or shape[2] != 3:
        raise ValueError(f"{path}: '{HDF5_DATASET}' has shape {shape}, expected (N, n, 3)")
    # a small file may declare a billion clouds (each an item of the batch: gigabytes before the
    # first fit): the whole dataset is capped like one cloud, its clouds by MAX_HDF5_CLOUDS
    check_dataset_size(path, shape, 8, f"'{HDF5_DATASET}'")
    if shape[0] > MAX_HDF5_CLOUDS:
        raise ValueError(f"{path}: '{HDF5_DATASET}' holds {shape[0]} clouds, more than the "
                         f"{MAX_HDF5_CLOUDS} a batch takes from one file; split the file")
    return int(shape[0])


def hdf5_points(path: str, index: int) -> np.ndarray:
    """Cloud ``index`` of an HDF5 file as a float64 (n, 3) array, checked like a cloud file."""
    import h5py
    import numpy as np

    from nurbs_core.io.cloud import check_points
    from nurbs_core.io.limits import check_dataset_size

    with h5py.File(path, "r") as handle:
        dataset = handle[HDF5_DATASET]
        check_dataset_size(path, dataset.shape[1:], 8, f"cloud {index}")
        points = np.asarray(dataset[index], dtype=np.float64)
    return check_points(f"{path}[{index}]", points)


def _file_items(path: Path) -> list[Item]:
    text = os.fspath(path)
    if path.suffix.lower() not in HDF5_SUFFIXES:
        return [Item(os.fspath(path), text, path.stem)]
    from nurbs_core.jobs import error_line

    try:
        count = hdf5_count(text)
    except Exception as exc:  # a bad HDF5 file is one failed input
        return [Item(os.fspath(path), text, path.stem, error=error_line(exc))]
    return [Item(f"{path}[{k}]", text, f"{path.stem}_{k}", index=k) for k in range(count)]


def _error(label: str, message: str) -> Item:
    return Item(label, label, Path(label).stem or "input", error=f"nurbs-fit: error: {message}")


def expand(inputs: list[str], exclude: tuple[Path, ...] = ()) -> list[Item]:
    """The items of ``inputs`` in order (a folder's point-cloud files sorted by name, a glob's
    matches sorted), each file once; ``exclude``: files never taken from a folder or glob (an
    earlier run's summary)."""
    suffixes = _cloud_suffixes()
    excluded = {os.path.realpath(p) for p in exclude}
    items: list[Item] = []
    seen: set[str] = set()

    def add(path: Path, listed: bool) -> None:
        real = os.path.realpath(path)
        if real in seen or (not listed and real in excluded):
            return
        seen.add(real)
        items.extend(_file_items(path))

    for text in inputs:
        path = Path(text)
        if path.is_dir():
            # hidden files are not inputs (a killed save's temporary ".name.1a2b.tmp.ply")
            files = sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith(".")
                           and p.suffix.lower() in suffixes)
            if not files:
                items.append(_error(text, f"{text}: the folder holds no point-cloud files "
                                          f"({', '.join(suffixes)})"))
            for file in files:
                add(file, listed=False)
        elif not path.exists() and _is_glob(text):
            matches = sorted(glob.glob(text, recursive=True))
            files = [Path(m) for m in matches
                     if Path(m).is_file() and not Path(m).name.startswith(".")]
            if not files:
                items.append(_error(text, f"{text}: no file matches"))
            for file in files:
                add(file, listed=False)
        else:  # a file, or a missing one: the fit reports it like a single run would
            add(path, listed=True)
    return items


def name_outputs(items: list[Item], directory: Path, suffix: str, offset: bool) -> None:
    """Give each item its result path(s) in ``directory``: ``<stem><suffix>`` (HDF5 items:
    ``<stem>_<k><suffix>``); inputs whose stems collide keep their whole name
    (``scan.ply.json``), then a counter; ``offset``: the ``<name>_offset<suffix>`` companion. A
    name is never one already given in this run (main or companion, letter case aside) nor an
    input file's: the counter goes on past those."""
    stems: dict[str, int] = {}
    for item in items:
        stems[item.name] = stems.get(item.name, 0) + 1
    inputs = {os.path.normcase(os.path.realpath(item.path)) for item in items}
    used: set[str] = set()

    def free(paths: list[Path]) -> bool:
        return not any(p.name.lower() in used or os.path.normcase(os.path.realpath(p)) in inputs
                       for p in paths)

    for item in items:
        name = item.name
        if stems[name] > 1 and item.index is None:
            name = Path(item.path).name
        base, k = name, 2

        def planned(stem: str) -> list[Path]:
            paths = [directory / f"{stem}{suffix}"]
            return paths + [directory / f"{stem}_offset{suffix}"] if offset else paths

        while not free(planned(name)):
            name, k = f"{base}_{k}", k + 1
        item.outputs = [os.fspath(p) for p in planned(name)]
        used.update(Path(p).name.lower() for p in item.outputs)


def check_planned_writes(items: list[Item], summary: Path, read: tuple[str | None, ...] = ()) -> None:
    """Every file the batch will write (each item's results, the summary) against every input
    (the items, and ``read``: the other files every fit reads, ``--initial``) and against each
    other, by file identity (symbolic and hard links, ``..``, letter case on a case-insensitive
    file system), before any work: OutputPathError naming both (or naming the folder that stands
    where a file is due)."""
    from nurbs_core.io.errors import OutputPathError
    from nurbs_core.io.outputs import same_file

    sources: dict[str, str] = {}
    for item in items:
        if item.error is None:
            sources.setdefault(os.path.realpath(item.path), item.path)
    for other in read:
        if other is not None and os.path.exists(other):
            sources.setdefault(os.path.realpath(other), other)
    writes = [(Path(p), f"the result of {item.label}") for item in items for p in item.outputs]
    writes.append((summary, "the summary"))
    for path, what in writes:
        if path.is_dir():
            raise OutputPathError(path, f"a folder is in the way of {what}; move it or choose "
                                        "another --output-dir")
        for source in sources.values():
            if same_file(path, Path(source)):
                raise OutputPathError(path, f"{what} would overwrite the input {source}; choose "
                                            "another name or folder")
    seen: dict[str, tuple[Path, str]] = {}
    for path, what in writes:
        key = os.path.normcase(os.path.realpath(path)).lower()
        if key in seen:
            raise OutputPathError(path, f"{what} and {seen[key][1]} would both be written here")
        seen[key] = (path, what)
