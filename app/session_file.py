"""The session file: one zip archive (stored, not compressed) holding ``session.json`` (the
settings, the length unit, the names, the fitted and loaded surfaces, the patch network's
report), the solid of Solid mode (``solid.json``: its B-rep text and face report,
:mod:`app.solid_session`) and the arrays as ``.npy`` members (the clouds' points, the network's
deviation, the solid's per-point distances and faces), and the patch network as our lossless
network JSON (``network.json``, :mod:`nurbs_core.io.network_io`).

Binary points make a 1,000,000-point session about 24 MB, written and read in a fraction of a
second (JSON took 60 MB and 7 s). Reading is bounded and never runs code: members must be
stored (no compression, so no bomb), no larger than the file, arrays are read with
``allow_pickle=False`` after their header is checked (a numeric dtype, a size that fits the
member). Qt-free and torch-free.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.state import (
    JSON_SESSION_FORMAT,
    OLD_SESSION_FORMATS,
    Document,
    FileOrder,
    Settings,
    Target,
)
from nurbs_core.geometry_arrays import from_mapping, number_array
from nurbs_core.io.json_format import json_kind

#: The archive's manifest format (sessions of the JSON formats before it are still read).
ARCHIVE_FORMAT = "nurbs-studio-session-v3"
SESSION_SUFFIX = ".nstudio"
MANIFEST = "session.json"
#: At most this many members (a session holds a few clouds and one network).
MAX_MEMBERS = 10_000


def is_archive(path: str | Path) -> bool:
    """Whether ``path`` is a zip archive (a session of the current format)."""
    try:
        return zipfile.is_zipfile(path)
    except OSError:
        return False


#: Bytes written between two progress reports and cancel checks while an array is written.
WRITE_CHUNK = 1 << 20


class _ReportingWriter:
    """A zip member's writer that writes in :data:`WRITE_CHUNK` pieces, calling ``step(bytes)``
    after each (progress, and a cancel check that may raise)."""

    def __init__(self, member: Any, step: Callable[[int], None]):
        self._member, self._step = member, step

    def write(self, data: Any) -> int:
        view = memoryview(data).cast("B")
        for start in range(0, len(view), WRITE_CHUNK):
            piece = view[start:start + WRITE_CHUNK]
            self._member.write(piece)
            self._step(len(piece))
        return len(view)


def write_archive(path: str | Path, manifest: dict[str, Any], arrays: dict[str, np.ndarray],
                  documents: dict[str, dict[str, Any]],
                  report: Callable[[float], None] | None = None,
                  check: Callable[[], None] | None = None) -> None:
    """Write the session atomically: ``manifest`` as ``session.json``, each array as
    ``<name>.npy``, each document as JSON under its name. JSON and arrays are encoded before the
    file is touched (a failure writes nothing and leaves an existing file as it was).
    ``report(fraction)``: told how much of the data is written; ``check()``: called between
    pieces of about :data:`WRITE_CHUNK` bytes, may raise to stop (a cancel): the file is then
    left as it was too."""
    from nurbs_core.atomic import atomic_write

    texts = {MANIFEST: json.dumps(manifest, allow_nan=False)}
    texts.update({name: json.dumps(document, allow_nan=False)
                  for name, document in documents.items()})
    total = max(1, sum(len(text) for text in texts.values())
                + sum(int(array.nbytes) for array in arrays.values()))
    written = 0

    def step(count: int) -> None:
        nonlocal written
        written += count
        if check is not None:
            check()
        if report is not None:
            report(written / total)

    with atomic_write(path, "wb") as handle, \
            zipfile.ZipFile(handle, "w", zipfile.ZIP_STORED, allowZip64=True) as archive:
        for name, text in texts.items():
            archive.writestr(name, text)
            step(len(text))
        for name, array in arrays.items():
            with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(_ReportingWriter(member, step),
                                          np.ascontiguousarray(array), allow_pickle=False)


class SessionArchive:
    """An open session archive, checked member by member as it is read (ValueError naming the
    member for anything malformed). Use as a context manager."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            self._zip = zipfile.ZipFile(self.path)
        except (OSError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{self.path}: not a readable session file ({exc})") from None
        members = self._zip.infolist()
        size = os.path.getsize(self.path)
        if len(members) > MAX_MEMBERS:
            raise ValueError(f"{self.path}: {len(members)} members, more than a session holds")
        for member in members:
            if member.compress_type != zipfile.ZIP_STORED or member.file_size > size:
                raise ValueError(f"{self.path}: member {member.filename} is compressed or larger "
                                 "than the file (sessions store their members as they are)")
        self.names = {member.filename for member in members}
        self._arrays_read: set[str] = set()

    def __enter__(self) -> SessionArchive:
        return self

    def __exit__(self, *_: object) -> None:
        self._zip.close()

    def _bytes(self, name: str) -> bytes:
        if name not in self.names:
            raise ValueError(f"the session lacks {name}")
        try:
            return self._zip.read(name)
        except (OSError, zipfile.BadZipFile) as exc:  # a CRC error: a damaged member
            raise ValueError(f"{name} is damaged ({exc})") from None

    def document(self, name: str) -> Any:
        """The JSON member ``name``, parsed."""
        try:
            return json.loads(self._bytes(name))
        except RecursionError:
            raise ValueError(f"{name} is nested too deeply to be a session's JSON") from None
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{name} is not valid JSON ({exc})") from None

    def array(self, name: str) -> np.ndarray:
        """The array ``<name>.npy``: numeric (bool, integer or floating point), its header
        checked against the member's size before any data is read. Each array is read once:
        a manifest naming one member for every cloud would have it copied as often (10,000
        clouds of one 24 MB member: 240 GB from a 24 MB file)."""
        if name in self._arrays_read:
            raise ValueError(f"{name}.npy is named twice in the session (each cloud and map has "
                             "its own)")
        self._arrays_read.add(name)
        data = self._bytes(f"{name}.npy")
        stream = io.BytesIO(data)
        try:
            version = np.lib.format.read_magic(stream)
            header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                      else np.lib.format.read_array_header_2_0)
            shape, _, dtype = header(stream)
        except (ValueError, OSError, SyntaxError) as exc:
            raise ValueError(f"{name}.npy is not an array file ({exc})") from None
        if dtype.kind not in "biuf" or dtype.hasobject:
            raise ValueError(f"{name}.npy holds {dtype}, not numbers")
        if int(np.prod(shape, dtype=np.int64)) * dtype.itemsize > len(data) - stream.tell():
            raise ValueError(f"{name}.npy declares {shape} values, more than it holds")
        stream.seek(0)
        try:
            return np.lib.format.read_array(stream, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise ValueError(f"{name}.npy is damaged ({exc})") from None


@dataclass(frozen=True)
class SessionContent:
    """What a save writes, taken from the document at one moment (on the GUI thread, cheaply:
    the arrays and the network and solid are referenced, never copied; the app replaces them,
    it never changes them in place). ``manifest``: the session's JSON; ``arrays``: name -> array
    (the clouds' points (N, 3), the network's deviation (N,), the solid's per-point arrays);
    ``network`` (a PatchNetwork) and ``solid`` (a PartOutcome) are turned into their documents
    by :func:`write_session`, off the GUI thread."""

    manifest: dict[str, Any]
    arrays: dict[str, np.ndarray]
    network: Any = None
    solid: Any = None


def session_content(document: Document,
                    network_report: dict[str, Any] | None = None) -> SessionContent:
    """The session of ``document`` with its patch network when one is shown and
    ``network_report`` (its quality, warnings, pass count, time and per-point ``deviation``
    (N,)), ready for :func:`write_session`."""
    arrays = {f"targets/{k}": t.points for k, t in enumerate(document.targets)}
    targets = [{"name": t.name, "path": t.path, "visible": t.visible, "points": f"targets/{k}",
                "as_read": as_read(t)} for k, t in enumerate(document.targets)]
    for k, target in enumerate(document.targets):
        if target.file_order is not None and as_read(target):
            # a curve fits the file's points as listed (repeats too): kept with the session
            arrays[f"targets/{k}/listed"] = target.file_order.points
            arrays[f"targets/{k}/rows"] = target.file_order.rows
            targets[k]["file_order"] = {"points": f"targets/{k}/listed",
                                        "rows": f"targets/{k}/rows"}
    manifest: dict[str, Any] = {
        "format": ARCHIVE_FORMAT,
        "settings": document.settings.to_json(),
        "units": document.units,
        "targets": targets,
        "patches": [{"name": name, "geometry": g.to_json()}
                    for name, g in zip(document.patch_names, document.patches, strict=True)],
        "fitted": None if document.fitted is None else document.fitted.to_json(),
        "network": None, "network_report": None,
    }
    if document.network is not None:
        manifest["network"] = "network.json"
        report = dict(network_report or {})
        deviation = report.pop("deviation", None)
        if deviation is not None:
            arrays["network_deviation"] = np.asarray(deviation, np.float64)
            report["deviation"] = "network_deviation"
        manifest["network_report"] = report
    if document.solid is not None:
        from app.solid_session import SOLID_MEMBER

        manifest["solid"] = SOLID_MEMBER
    return SessionContent(manifest, arrays, document.network, document.solid)


def write_session(content: SessionContent, path: str | Path,
                  report: Callable[[float], None] | None = None,
                  check: Callable[[], None] | None = None) -> None:
    """Write ``content`` as a session file, atomically: ``path`` is replaced only by a complete
    file (a failed write, or ``check()`` raising, leaves an existing file as it was).
    ``report`` and ``check``: as :func:`write_archive` takes them."""
    arrays, documents = dict(content.arrays), {}
    if content.network is not None:
        from nurbs_core.io.network_io import network_document

        documents[content.manifest["network"]] = network_document(content.network)
    if content.solid is not None:
        from app.solid_session import solid_document

        documents[content.manifest["solid"]], solid_arrays = solid_document(content.solid)
        arrays.update(solid_arrays)
    write_archive(path, content.manifest, arrays, documents, report, check)


def save_session(document: Document, path: str | Path,
                 network_report: dict[str, Any] | None = None) -> None:
    """Write ``document`` as a session (see the module docstring and :func:`session_content`)
    in this thread, atomically."""
    write_session(session_content(document, network_report), path)


def read_session(path: str | Path) -> dict[str, Any]:
    """Parse and check a session file (an archive, or a JSON session of the formats before it)
    without touching any document; raises ValueError naming the problem. Returns settings,
    targets, patches, names, fitted, network (a PatchNetwork or None), network_report, solid (a
    PartOutcome or None) (for
    :meth:`app.state.Document.apply_session`; the network is the window's to show) and units
    (the length unit, None: unknown)."""
    path = Path(path)
    if is_archive(path):
        try:
            with SessionArchive(path) as archive:
                if MANIFEST not in archive.names:
                    raise ValueError(f"{path}: not a NURBS Studio session (a zip archive "
                                     f"without {MANIFEST})")
                data = archive.document(MANIFEST)
                if not isinstance(data, dict) or data.get("format") != ARCHIVE_FORMAT:
                    raise ValueError(f"not a NURBS Studio session (expected format "
                                     f"{ARCHIVE_FORMAT!r})")
                return _parsed_session(path, data, archive)
        except ValueError as exc:
            message = str(exc)
            raise ValueError(message if message.startswith(str(path))
                             else f"{path}: damaged session ({message})") from None
    data = _json_session(path)
    if not isinstance(data, dict) or data.get("format") not in (JSON_SESSION_FORMAT,
                                                                 *OLD_SESSION_FORMATS):
        raise ValueError(f"{path}: not a NURBS Studio session (expected format "
                         f"{ARCHIVE_FORMAT!r})")
    try:
        return _parsed_session(path, data, None)
    except ValueError as exc:
        raise ValueError(f"{path}: damaged session ({exc})") from None


def _json_session(path: Path) -> Any:
    """The parsed document of a file that is no zip archive: a JSON session of the formats
    before the archive, read as a JSON file is (bounded: :func:`read_json_file`); ValueError
    saying what the file is instead (a truncated archive, binary data, invalid JSON)."""
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.io.json_format import read_json_file

    try:
        with open(path, "rb") as handle:
            head = handle.read(4)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the session file ({exc.strerror or exc})") from None
    if head.startswith(b"PK"):  # a zip's local header: an archive cut short or corrupted
        raise ValueError(f"{path}: damaged session (the archive is truncated or corrupt: its "
                         "zip directory does not read)")
    try:
        return read_json_file(path)
    except FileFormatError as exc:
        raise ValueError(f"{path}: not a NURBS Studio session (neither a session archive nor "
                         f"a JSON session: {exc.problem})") from None


def as_read(target: Target) -> bool:
    """Whether the target's points are still the ones its file gave (no point deleted)."""
    return target.read_points is not None and target.points is target.read_points


def _file_order(number: int, item: dict[str, Any], points: np.ndarray,
                archive: Any) -> FileOrder | None:
    """A session target's file order (its points as listed and the row of them each point is),
    checked against its points; None when the session keeps none (older sessions)."""
    entry = item.get("file_order")
    if entry is None or archive is None:
        return None
    if not isinstance(entry, dict) or not all(isinstance(entry.get(key), str)
                                              for key in ("points", "rows")):
        raise ValueError(f"targets[{number}].file_order needs the names of its points and rows")
    listed = archive.array(entry["points"])
    rows = archive.array(entry["rows"])
    if listed.ndim != 2 or listed.shape[1:] != (3,) or rows.ndim != 1 \
            or not np.issubdtype(rows.dtype, np.integer) or len(rows) != len(points):
        raise ValueError(f"targets[{number}].file_order: {listed.shape} points and "
                         f"{rows.shape} rows of {rows.dtype} do not list {len(points)} points")
    if len(rows) and (rows.min() < 0 or rows.max() >= len(listed)
                      or not np.array_equal(listed[rows], points)):
        raise ValueError(f"targets[{number}].file_order does not list the target's points")
    return FileOrder(np.asarray(listed, np.float64), np.asarray(rows, np.int64))


def load_session(document: Document, path: str | Path) -> dict[str, Any]:
    """Read a session file and apply it to ``document`` (untouched when the file is refused:
    ValueError); returns the session (its network is the window's to show)."""
    session = read_session(path)
    document.apply_session(session)
    return session


def _session_target(number: int, item: Any) -> Target:
    """A session's point cloud, checked like a cloud file (nurbs_core.io.cloud.check_points: an
    (N, 3) array of finite numbers within the range the fit computes in; never regrouped from
    another shape; an empty cloud stays allowed); ValueError naming it."""
    from nurbs_core.io.cloud import check_points
    from nurbs_core.io.errors import FileFormatError

    if not isinstance(item, dict) or not isinstance(item.get("name"), str):
        raise ValueError(f"targets[{number}] needs a name")
    path, visible = item.get("path", ""), item.get("visible", True)
    if not isinstance(path, str):
        raise ValueError(f"targets[{number}].path must be text, got {path!r}")
    if not isinstance(visible, bool):  # "no" is text: never read as true
        raise ValueError(f"targets[{number}].visible must be true or false, got {visible!r}")
    if "points" not in item:
        raise ValueError(f"targets[{number}] ({item['name']}) needs its points")
    points = number_array(f"targets[{number}].points", item["points"])
    if points.size == 0:
        points = points.reshape(0, 3)
    else:
        try:
            check_points(f"targets[{number}] ({item['name']})", points)
        except FileFormatError as exc:
            raise ValueError(str(exc)) from None
    return Target(item["name"], points, path, visible)


def _list(data: dict[str, Any], key: str) -> list[Any]:
    """``data[key]`` when it is a list (missing: empty); ValueError naming it otherwise."""
    value = data.get(key, [])
    if not isinstance(value, list):
        raise ValueError(f"{key} must be a list, got {type(value).__name__}")
    return value


def _parsed_session(path: Path, data: dict[str, Any], archive: Any) -> dict[str, Any]:
    """The checked content of a session's manifest (``archive``: its SessionArchive, whose
    members hold the points and the network; None for a JSON session, which holds its points
    as lists). ValueError for anything malformed."""
    try:
        settings = _session_settings(data)
        targets = []
        for number, item in enumerate(_list(data, "targets")):
            if archive is not None and isinstance(item, dict):
                if not isinstance(item.get("points"), str):
                    raise ValueError(f"targets[{number}] needs the name of its points")
                item = {**item, "points": archive.array(item["points"])}
            target = _session_target(number, item)
            if item.get("as_read") is True:
                # the points as the file gave them: a curve fits them in the file's order
                target.read_points = target.points
                target.file_order = _file_order(number, item, target.points, archive)
            targets.append(target)
        patches, names = [], []
        for number, item in enumerate(_list(data, "patches")):
            if not isinstance(item, dict) or not isinstance(item.get("name"), str):
                raise ValueError(f"patches[{number}] needs a name (text) and a geometry")
            if "geometry" not in item:
                raise ValueError(f"patches[{number}] ({item['name']}) needs its geometry")
            patches.append(_geometry(f"patches[{number}] ({item['name']})", item["geometry"]))
            names.append(item["name"])
        fitted = data.get("fitted")
        fitted = None if fitted is None else _geometry("fitted", fitted)
        units = _session_units(data, targets)
        network, report = None, None
        if archive is not None and data.get("network") is not None:
            network, report = _session_network(path, data, archive)
        solid = None
        if archive is not None and data.get("solid") is not None:
            solid = _session_solid(data, archive)
    except KeyError as exc:  # a checked entry lacks a field the checks above did not name
        raise ValueError(f"an entry lacks its {exc.args[0]!r}") from None
    except TypeError as exc:
        raise ValueError(f"a value of the wrong type ({exc})") from None
    return {"settings": settings, "targets": targets, "patches": patches, "names": names,
            "fitted": fitted, "network": network, "network_report": report, "units": units,
            "solid": solid}


def _session_settings(data: dict[str, Any]) -> Settings:
    """The session's settings, checked (:meth:`Settings.validate`: the bounds nurbs-fit
    keeps); ValueError naming what is wrong. Each part must be an object first: ``"fit":
    "fast"`` was read letter by letter ("unknown fit settings: a, f, s, t")."""
    value = data.get("settings", {})
    if not isinstance(value, dict):
        raise ValueError(f"settings must be an object, got {json_kind(value)}")
    if data["format"] == OLD_SESSION_FORMATS[0]:
        settings = Settings.from_flat_json(value)
    else:
        for part in ("fit", "patches"):
            if part in value and not isinstance(value[part], dict):
                raise ValueError(f"settings.{part} must be an object, "
                                 f"got {json_kind(value[part])}")
        settings = Settings.from_json(value)
    settings.validate()
    return settings


def _session_solid(data: dict[str, Any], archive: Any) -> Any:
    """The session's solid (:mod:`app.solid_session`), checked."""
    from app.solid_session import DISTANCES, POINT_FACES, solid_from_document

    name = data["solid"]
    if not isinstance(name, str):
        raise ValueError("solid must name its member")
    return solid_from_document(archive.document(name),
                               {DISTANCES: archive.array(DISTANCES),
                                POINT_FACES: archive.array(POINT_FACES)})


def _geometry(name: str, data: Any) -> Any:
    """A session's curve or surface (:func:`from_mapping`, strict about types); ValueError
    naming where it is."""
    if not isinstance(data, dict):
        raise ValueError(f"{name} must be an object")
    try:
        geometry = from_mapping(data)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    # one shape: a batch of them (control points (B, n, m, 3)) is what a fit's snapshot may
    # carry, never what the window shows
    net_dims = 3 if geometry.kind == "surface" else 2
    if np.ndim(geometry.control_points) != net_dims:
        raise ValueError(f"{name}: control points of shape "
                         f"{np.shape(geometry.control_points)} are several shapes, not one")
    return geometry


def _session_units(data: dict[str, Any], targets: list[Target]) -> str | None:
    """The session's length unit (None: unknown). Sessions from before units were kept have
    none: their clouds' files say it where their format does (E57: metres), as the window
    showed it then."""
    from nurbs_core.io.units import check_units, units_of_file

    if "units" in data:
        units = data["units"]
        if units is not None and not isinstance(units, str):
            raise ValueError("units must be text or null")
        return check_units(units)
    stated = {units_of_file(t.path) for t in targets}
    return stated.pop() if len(stated) == 1 else None


def _session_network(path: Path, data: dict[str, Any], archive: Any) -> tuple[Any, dict]:
    """The session's patch network (checked as a network file is) and its report."""
    from nurbs_core.io.errors import FileFormatError
    from nurbs_core.io.network_io import network_from_document

    name = data["network"]
    if not isinstance(name, str):
        raise ValueError("network must name its member")
    try:
        network = network_from_document(name, archive.document(name))
    except FileFormatError as exc:
        raise ValueError(f"the patch network ({name}): {exc.problem}") from None
    report = data.get("network_report") or {}
    if not isinstance(report, dict):
        raise ValueError("network_report must be an object")
    report = dict(report)
    _check_report(report)
    if isinstance(report.get("deviation"), str):
        deviation = archive.array(report["deviation"])
        if deviation.ndim != 1:
            raise ValueError(f"the network's deviation must be one value per point, got "
                             f"shape {deviation.shape}")
        deviation = deviation.astype(np.float64)
        # NaN marks a point left out of the fit (a fit of a selection); none fitted, or an
        # infinite distance, is a damaged file
        if deviation.size and np.isnan(deviation).all():
            raise ValueError("network_report.deviation is NaN at every point")
        if np.isinf(deviation).any():
            raise ValueError("network_report.deviation holds infinite values")
        report["deviation"] = deviation
    elif report.get("deviation") is not None:
        raise ValueError("network_report.deviation must name its member")
    else:
        report.pop("deviation", None)
    return network, report


def _check_report(report: dict[str, Any]) -> None:
    """The stored report of a network fit (``PatchController.network_report``): each field it
    holds of the type that method writes (NaN stored as null); ValueError naming the first that
    is not."""
    def number(value: Any) -> bool:
        return isinstance(value, (int, float)) and not isinstance(value, bool)

    def quality(value: Any) -> bool:  # numbers, true/false, null, and mappings of those
        return all(item is None or isinstance(item, (bool, int, float))
                   or (isinstance(item, dict) and quality(item)) for item in value.values())

    if report.get("event", "done") not in ("done", "stopped"):
        raise ValueError(f"network_report.event must be 'done' or 'stopped', got "
                         f"{report['event']!r}")
    if report.get("quality") is not None and not (isinstance(report["quality"], dict)
                                                  and quality(report["quality"])):
        raise ValueError("network_report.quality must be an object of numbers")
    warnings = report.get("warnings", [])
    if not (isinstance(warnings, list) and all(isinstance(w, str) for w in warnings)):
        raise ValueError("network_report.warnings must be a list of text")
    passes = report.get("passes", 0)
    if isinstance(passes, bool) or not isinstance(passes, int) or passes < 0:
        raise ValueError(f"network_report.passes must be a whole number, got {passes!r}")
    if not (number(report.get("elapsed", 0.0)) and report.get("elapsed", 0.0) >= 0):
        raise ValueError(f"network_report.elapsed must be a number of seconds, got "
                         f"{report['elapsed']!r}")
    for name in ("rms", "seam"):
        if report.get(name) is not None and not number(report[name]):
            raise ValueError(f"network_report.{name} must be a number or null, got "
                             f"{report[name]!r}")
