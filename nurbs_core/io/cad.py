"""STEP and IGES through OCP (``cadquery-ocp-novtk``), an optional extra.

Writing: each surface becomes a B-spline face (STEP ``B_SPLINE_SURFACE_WITH_KNOTS``, IGES entity
128), each curve an edge, all in one compound. STEP and IGES (and OpenCASCADE) store distinct
knots plus multiplicities; the full vector is split exactly, so unclamped vectors keep their
end knots. Reading: every face's untrimmed surface (its placement applied), converted to a
B-spline when it is an analytic surface; when a file has no faces, its edges as curves.
OpenCASCADE converts lengths to millimetres on reading (files are written in millimetres).
Reals are written with 17 significant digits, so float64 geometry round-trips exactly.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import io
import json
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from nurbs_core.io.errors import FileFormatError, StrPath, require_ocp
from nurbs_core.io.limits import configured_size
from nurbs_core.occ_topology import OccObject, subshapes

if TYPE_CHECKING:
    from nurbs_core.geometry import NurbsCurve, NurbsSurface
    from nurbs_core.io.geometry_io import GeometryInput, Writable


STEP_SUFFIXES = (".step", ".stp")
IGES_SUFFIXES = (".iges", ".igs")


def distinct_knots(knots: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Full knot vector (m,) -> (distinct values, multiplicities), exact (no tolerance)."""
    values, counts = np.unique(np.asarray(knots, dtype=np.float64), return_counts=True)
    return values, counts


_QUIETED = False


def triangulate(shape: OccObject, deflection: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shape's triangles within ``deflection`` of its faces: vertices (V, 3), triangles
    (T, 3) oriented outwards, and each triangle's face index (T,) into ``subshapes(shape, "FACE")``."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopAbs import TopAbs_Orientation
    from OCP.TopLoc import TopLoc_Location

    BRepMesh_IncrementalMesh(shape, deflection, False, 0.3, False)
    vertices, triangles, owners = [], [], []
    offset = 0
    for index, face in enumerate(subshapes(shape, "FACE")):
        location = TopLoc_Location()
        mesh = BRep_Tool.Triangulation_s(face, location)
        if mesh is None:
            continue
        transform = location.Transformation()
        nodes = np.array([mesh.Node(k).Transformed(transform).Coord()
                          for k in range(1, mesh.NbNodes() + 1)])
        tris = np.array([mesh.Triangle(k).Get() for k in range(1, mesh.NbTriangles() + 1)]) - 1
        if face.Orientation() == TopAbs_Orientation.TopAbs_REVERSED:
            tris = tris[:, ::-1]
        vertices.append(nodes)
        triangles.append(tris + offset)
        owners.append(np.full(len(tris), index))
        offset += len(nodes)
    if not triangles:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    return (np.concatenate(vertices), np.concatenate(triangles).astype(np.int64),
            np.concatenate(owners))


def quiet_occ() -> None:
    """Stop OpenCASCADE's default messenger from printing transfer statistics to stdout."""
    global _QUIETED
    if _QUIETED:
        return
    from OCP.Message import Message, Message_PrinterOStream

    Message.DefaultMessenger_s().RemovePrinters(Message_PrinterOStream.get_type_descriptor_s())
    _QUIETED = True


def _array1_double(values: Sequence[float] | np.ndarray) -> OccObject:
    from OCP.collections import Array1_double

    array = Array1_double(1, len(values))
    for k, value in enumerate(values, start=1):
        array.SetValue(k, float(value))
    return array


def _array1_int(values: Sequence[int] | np.ndarray) -> OccObject:
    from OCP.collections import Array1_int

    array = Array1_int(1, len(values))
    for k, value in enumerate(values, start=1):
        array.SetValue(k, int(value))
    return array


def occ_surface(data: dict[str, Any]) -> OccObject:
    """A ``Geom_BSplineSurface`` from a surface's ``numpy()`` dict (control points (n_u, n_v, 3),
    weights (n_u, n_v), full knot vectors)."""
    from OCP.collections import Array2_double, Array2_gp_Pnt
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt

    control, weights = data["control_points"], data["weights"]
    n_u, n_v = control.shape[:2]
    poles = Array2_gp_Pnt(1, n_u, 1, n_v)
    weight_array = Array2_double(1, n_u, 1, n_v)
    for i in range(n_u):
        for j in range(n_v):
            x, y, z = control[i, j]
            poles.SetValue(i + 1, j + 1, gp_Pnt(float(x), float(y), float(z)))
            weight_array.SetValue(i + 1, j + 1, float(weights[i, j]))
    knots_u, mults_u = distinct_knots(data["knots_u"])
    knots_v, mults_v = distinct_knots(data["knots_v"])
    return Geom_BSplineSurface(poles, weight_array, _array1_double(knots_u),
                               _array1_double(knots_v), _array1_int(mults_u),
                               _array1_int(mults_v), int(data["degree_u"]),
                               int(data["degree_v"]), False, False)


def occ_curve(data: dict[str, Any]) -> OccObject:
    """A ``Geom_BSplineCurve`` from a curve's ``numpy()`` dict (control points (n, 2) or (n, 3),
    weights (n,); 2-D curves get z = 0)."""
    from OCP.collections import Array1_gp_Pnt
    from OCP.Geom import Geom_BSplineCurve
    from OCP.gp import gp_Pnt

    control = data["control_points"]
    n, dimension = control.shape
    poles = Array1_gp_Pnt(1, n)
    for k in range(n):
        xyz = [float(c) for c in control[k]] + [0.0] * (3 - dimension)
        poles.SetValue(k + 1, gp_Pnt(*xyz))
    knots, mults = distinct_knots(data["knots"])
    return Geom_BSplineCurve(poles, _array1_double(data["weights"]), _array1_double(knots),
                             _array1_int(mults), int(data["degree"]), False)


def _compound(items: Iterable[Writable]) -> OccObject:
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace
    from OCP.TopoDS import TopoDS_Compound

    builder = BRep_Builder()
    compound = TopoDS_Compound()
    builder.MakeCompound(compound)
    for index, item in enumerate(items):
        from nurbs_core.io.geometry_io import numpy_of

        data = numpy_of(item)
        try:
            if data["kind"] == "surface":
                shape = BRepBuilderAPI_MakeFace(occ_surface(data), 1e-7).Face()
            else:
                shape = BRepBuilderAPI_MakeEdge(occ_curve(data)).Edge()
        except Exception as exc:  # OpenCASCADE's Standard_Failure family
            raise ValueError(f"OpenCASCADE rejects item {index} ({item!r}): "
                             f"{type(exc).__name__}: {exc}") from None
        builder.Add(compound, shape)
    return compound


def step_bytes(shape: OccObject, path: StrPath, units: str | None = None) -> bytes:
    """The STEP (AP214) text of an OCP shape, every real written as %.16E (17 significant
    digits, exact for float64), its length unit ``units`` (:mod:`nurbs_core.io.units`;
    millimetres when None; the coordinates are not scaled); ``path`` names the file in errors
    (OSError).

    STEPControl_Writer's own Write keeps 13 significant digits (a few 1e-9 off at coordinates
    of 1e4), so the model is printed here with a finer FloatWriter.
    """
    require_ocp("Writing STEP")
    quiet_occ()
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_StepModelType, STEPControl_Writer
    from OCP.StepData import StepData_StepWriter

    writer = STEPControl_Writer()
    with _occ_units(units, "write.step.unit"):
        status = writer.Transfer(shape, STEPControl_StepModelType.STEPControl_AsIs)
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise OSError(f"{path}: OpenCASCADE could not translate the geometry to STEP ({status})")
    printer = StepData_StepWriter(writer.Model())
    printer.FloatWriter().SetFormat("%.16E", True)
    printer.SendModel(writer.WS().NormAdaptor().Protocol())
    stream = io.BytesIO()
    if not printer.Print(stream):
        raise OSError(f"{path}: OpenCASCADE could not print the STEP model")
    return stream.getvalue()


@contextlib.contextmanager
def _occ_units(units: str | None, key: str) -> Iterator[None]:
    """OpenCASCADE's session unit and the writer's unit (``key``) both set to ``units`` for the
    block (equal, so no coordinate is scaled), then the session unit restored."""
    from OCP.Interface import Interface_Static

    from nurbs_core.io.units import occ_unit

    unit = occ_unit(units)
    session = Interface_Static.CVal_s("xstep.cascade.unit")
    Interface_Static.SetCVal_s("xstep.cascade.unit", unit)
    Interface_Static.SetCVal_s(key, unit)
    try:
        yield
    finally:
        Interface_Static.SetCVal_s("xstep.cascade.unit", session)


def iges_bytes(shape: OccObject, path: StrPath, brep: bool = False,
               units: str | None = None) -> bytes:
    """The IGES text of an OCP shape in ``units`` (millimetres when None; not scaled), every
    real written as %.16E (17 significant digits, exact for float64); ``path`` names the file
    in errors (OSError). Faces are trimmed
    surfaces (entities 128 + 144), or with ``brep`` IGES 5.3 B-rep entities (shells 514 of faces
    510, solids 186), which keep the shared-edge topology.

    IGESControl_Writer's own Write uses OpenCASCADE's default real format (10 significant
    digits, ~1e-10 relative error), so the model is printed here with a finer FloatWriter.
    """
    require_ocp("Writing IGES")
    quiet_occ()
    from OCP.IGESControl import IGESControl_Writer
    from OCP.IGESData import IGESData_IGESWriter
    from OCP.IGESSelect import IGESSelect_WorkLibrary

    from nurbs_core.io.units import occ_unit

    with _occ_units(units, "write.iges.unit"):
        writer = IGESControl_Writer(occ_unit(units), 1 if brep else 0)
        if not writer.AddShape(shape):
            raise OSError(f"{path}: OpenCASCADE could not translate the geometry to IGES")
        writer.ComputeModel()
    printer = IGESData_IGESWriter(writer.Model())
    printer.FloatWriter().SetFormat("%.16E", True)
    printer.SendModel(IGESSelect_WorkLibrary.DefineProtocol_s())
    stream = io.BytesIO()
    if not printer.Print(stream):
        raise OSError(f"{path}: OpenCASCADE could not print the IGES model")
    return stream.getvalue()


def write_step(geometry_or_list: GeometryInput, path: StrPath, units: str | None = None) -> None:
    """STEP (AP214): the geometry as one compound of faces and edges (see :func:`step_bytes`)."""
    require_ocp("Writing STEP")
    from nurbs_core.io.geometry_io import as_geometry_list

    data = step_bytes(_compound(as_geometry_list(geometry_or_list)), path, units)
    with open(path, "wb") as handle:
        handle.write(data)


def write_iges(geometry_or_list: GeometryInput, path: StrPath, units: str | None = None) -> None:
    """IGES: the geometry as trimmed surfaces and curves (see :func:`iges_bytes`)."""
    require_ocp("Writing IGES")
    from nurbs_core.io.geometry_io import as_geometry_list

    data = iges_bytes(_compound(as_geometry_list(geometry_or_list)), path, units=units)
    with open(path, "wb") as handle:
        handle.write(data)


#: The longest a read in the worker may take (in CPU seconds where Linux tells them, else wall
#: seconds): ``READ_BASE_SECONDS`` plus ``READ_SECONDS_PER_MIB`` per MiB of file, at most
#: ``READ_TIMEOUT_SECONDS`` (a damaged file can keep OpenCASCADE or openNURBS busy for good).
READ_TIMEOUT_SECONDS = 600.0
READ_BASE_SECONDS = 2.0
READ_SECONDS_PER_MIB = 4.0
#: How long the worker may take to start (import numpy) or to import OCP / rhino3dm before it
#: counts as broken (not part of the read's time limit).
START_TIMEOUT_SECONDS = 120.0
#: The memory a read in the worker may allocate: twice the file's size plus this, or the size
#: given by the environment variable (bytes, or with a K/M/G/T suffix: ``8G``).
READER_MEMORY_SLACK = 512 * 2**20
READER_MEMORY_ENV = "NURBS_STUDIO_MAX_READER_MEMORY"


def read_timeout(size: int) -> float:
    """Seconds a worker read of a file of ``size`` bytes may take."""
    return min(READ_TIMEOUT_SECONDS, READ_BASE_SECONDS + READ_SECONDS_PER_MIB * size / 2**20)


def reader_memory(size: int) -> int:
    """Bytes a worker read of a file of ``size`` bytes may allocate (see READER_MEMORY_ENV)."""
    configured = configured_size(READER_MEMORY_ENV)
    return configured if configured is not None else 2 * int(size) + READER_MEMORY_SLACK


#: A read stopped by its time limit in CPU seconds still ends after this many times the limit in
#: wall-clock seconds (a child blocked without using the CPU).
WALL_TIME_FACTOR = 2.0


def _cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of a running process (Linux /proc), None where unknown."""
    try:
        with open(f"/proc/{pid}/stat") as handle:
            fields = handle.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


class _ReaderProcess:
    """The long-lived child running ``_occ_reader.py`` (OpenCASCADE and openNURBS may segfault,
    hang or allocate without bound on damaged files: a crash or a timeout ends the child, not the
    program, and the next read starts a new one)."""

    def __init__(self) -> None:
        self._process: subprocess.Popen[str] | None = None
        self._lock = threading.Lock()
        self._pending = b""  # bytes the child wrote past its last complete line

    def _start(self) -> subprocess.Popen[str]:
        script = Path(__file__).with_name("_occ_reader.py")
        # few malloc arenas: each reserves address space, which the child's memory cap counts
        environment = {**os.environ, "MALLOC_ARENA_MAX": "2"}
        # -I: the child sees neither this folder nor PYTHONPATH, only the installed packages
        return subprocess.Popen([sys.executable, "-I", str(script)], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                bufsize=1, env=environment)

    def _kill(self, process: subprocess.Popen[str]) -> None:
        process.kill()
        process.wait()
        self._process = None

    def _reply(self, process: subprocess.Popen[str], timeout: float,
               cpu: bool = False) -> dict[str, Any] | Literal["timeout"] | None:
        """The child's next line as a dict; None when it died, "timeout" when it took too long:
        ``timeout`` seconds, of the child's CPU time with ``cpu`` (where /proc tells it: a
        library looping burns CPU, a busy machine only stretches the wall time; the wall time
        is still capped at WALL_TIME_FACTOR x timeout)."""
        start, used_before = time.monotonic(), _cpu_seconds(process.pid) if cpu else None
        pending = self._pending
        assert process.stdout is not None  # started with stdout=PIPE
        descriptor = process.stdout.fileno()  # read unbuffered: select() sees only the pipe
        while b"\n" not in pending:
            elapsed = time.monotonic() - start
            used = elapsed if used_before is None else \
                (_cpu_seconds(process.pid) or used_before) - used_before
            if used > timeout or elapsed > WALL_TIME_FACTOR * timeout:
                return "timeout"
            wait = timeout - used if used_before is None else 0.25
            ready, _, _ = select.select([descriptor], [], [], max(0.01, wait))
            if ready:
                data = os.read(descriptor, 1 << 16)
                if not data:
                    return None
                pending += data
        line, pending = pending.split(b"\n", 1)
        self._pending = pending
        try:
            return json.loads(line)
        except ValueError:
            return None

    def request(self, path: str, kind: str, output: str, timeout: float,
                memory: int | None = None, shape_output: str | None = None) -> dict[str, Any]:
        with self._lock:
            if self._process is None or self._process.poll() is not None:
                self._pending = b""
                self._process = self._start()
                started = self._reply(self._process, START_TIMEOUT_SECONDS)
                if not isinstance(started, dict) or not started.get("ready"):
                    process = self._process
                    self._kill(process)
                    if started == "timeout":
                        return {"ok": False, "error": "the reader process did not start within "
                                                      f"{START_TIMEOUT_SECONDS:g} s"}
                    return {"ok": False, "crashed": process.returncode}
            process = self._process
            assert process.stdin is not None  # started with stdin=PIPE
            try:
                process.stdin.write(json.dumps({"path": path, "kind": kind, "output": output,
                                                "memory": memory,
                                                "shape_output": shape_output}) + "\n")
                process.stdin.flush()
            except BrokenPipeError:
                process.wait()
                self._process = None
                return {"ok": False, "crashed": process.returncode}
            reply = self._reply(process, START_TIMEOUT_SECONDS)  # importing the library
            if isinstance(reply, dict) and reply.get("reading"):
                reply = self._reply(process, timeout, cpu=True)
            if reply == "timeout":
                self._kill(process)
                return {"ok": False, "timeout": timeout}
            if not isinstance(reply, dict):  # the child died while reading this file
                process.wait()
                self._process = None
                return {"ok": False, "crashed": process.returncode}
            return reply

    def close(self) -> None:
        with self._lock:
            if self._process is not None and self._process.poll() is None:
                assert self._process.stdin is not None  # started with stdin=PIPE
                self._process.stdin.close()
                try:
                    self._process.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    self._process.kill()
                    self._process.wait()
            self._process = None


_READER = _ReaderProcess()
atexit.register(_READER.close)

_LIBRARIES = {"step": ("OpenCASCADE", "STEP"), "iges": ("OpenCASCADE", "IGES"),
              "brep": ("OpenCASCADE", ".brep"), "3dm": ("openNURBS (rhino3dm)", ".3dm")}


def read_in_worker(path: StrPath, kind: str,
                   timeout: float | None = None) -> list[NurbsCurve | NurbsSurface]:
    """Every surface and curve the worker process reads from ``path`` (``kind`` "step", "iges",
    "brep" or "3dm"), as validated geometry with ``.metadata`` (``"name"`` when the object has one,
    ``"units"`` when the file states a length unit :mod:`nurbs_core.io.units` knows); a crash,
    a timeout (``timeout`` seconds, by default :func:`read_timeout` of the file's size), running
    out of the memory cap (:func:`reader_memory`) or bad data: FileFormatError naming the
    file."""
    reply, arrays = worker_read(path, kind, timeout)
    return geometry_of_reply(path, kind, reply, arrays)


def worker_read(path: StrPath, kind: str, timeout: float | None = None,
                shape: Callable[[str], Any] | None = None
                ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The worker's reply for ``path`` and the item arrays it wrote (see ``_occ_reader.py``);
    FileFormatError for a crash, a timeout or an error. ``shape``: ask for the whole shape of a
    file with trimmed faces; when the reply has it, ``shape(brep_path)`` is called on its B-rep
    file while it exists and the reply's ``"shape"`` becomes what it returned."""
    library, label = _LIBRARIES[kind]
    with open(path, "rb") as handle:
        if not handle.read(1):
            raise FileFormatError(path, "the file is empty")
    size = os.path.getsize(path)
    timeout = read_timeout(size) if timeout is None else timeout
    # the result is built as torch geometry: import torch here while the worker starts and reads
    # (in parallel on two cores, a cold start costs the larger of the two instead of their sum)
    warm = threading.Thread(target=importlib.import_module, args=("nurbs_core.io.geometry_io",),
                            daemon=True)
    warm.start()
    arrays: dict[str, np.ndarray] = {}
    with tempfile.TemporaryDirectory(prefix="nurbs_io_") as folder:
        output, shape_output = os.path.join(folder, "items.npz"), os.path.join(folder, "shape.brep")
        reply = _READER.request(os.path.abspath(path), kind, output, timeout, reader_memory(size),
                                shape_output if shape is not None else None)
        if "crashed" in reply:
            raise FileFormatError(path, f"{library} crashed reading this {label} file "
                                        f"(exit status {reply['crashed']}): it is damaged or "
                                        f"uses something {library} cannot handle")
        if "timeout" in reply:
            raise FileFormatError(path, f"{library} was still reading this {label} file after "
                                        f"{reply['timeout']:.1f} s: stopped (a damaged file?)")
        if not reply["ok"]:
            raise FileFormatError(path, reply["error"])
        if reply.get("shape") and shape is not None:
            reply["shape"] = shape(shape_output)
        else:
            with np.load(output, allow_pickle=False) as data:
                arrays = {key: data[key] for key in data.files}
    warm.join()
    return reply, arrays


def geometry_of_reply(path: StrPath, kind: str, reply: dict[str, Any],
                      arrays: dict[str, np.ndarray]) -> list[NurbsCurve | NurbsSurface]:
    """The validated geometry of a worker's reply and item arrays (:func:`read_in_worker`)."""
    _library, label = _LIBRARIES[kind]
    from nurbs_core.io.geometry_io import make_curve, make_surface
    from nurbs_core.io.units import units_from_library

    units = units_from_library(reply.get("units"))

    result: list[NurbsCurve | NurbsSurface] = []
    for k in range(reply["count"]):
        degrees = arrays[f"degrees_{k}"]
        surface = str(arrays[f"kind_{k}"]) == "surface"
        default = f"face {k}" if surface else f"edge {k}"
        what = str(arrays[f"label_{k}"]) if f"label_{k}" in arrays else default
        item: NurbsCurve | NurbsSurface
        if surface:
            item = make_surface(path, arrays[f"control_{k}"], arrays[f"weights_{k}"],
                                arrays[f"knots_u_{k}"], arrays[f"knots_v_{k}"],
                                degrees[0], degrees[1], what=what)
        else:
            item = make_curve(path, arrays[f"control_{k}"], arrays[f"weights_{k}"],
                              arrays[f"knots_{k}"], degrees[0], what=what)
        name = str(arrays[f"name_{k}"]) if f"name_{k}" in arrays else ""
        item.metadata = {"name": name} if name else {}
        if units is not None:  # the length unit the file states (never scaled)
            item.metadata["units"] = units
        result.append(item)
    if not result:
        raise FileFormatError(path, f"the {label} file has no surfaces or curves "
                                    f"({reply.get('objects', 0)} object(s) of other kinds)")
    return result


def read_cad(path: StrPath, kind: str,
             timeout: float | None = None) -> list[NurbsCurve | NurbsSurface]:
    """All surfaces (untrimmed) of a STEP or IGES file; its curves when it has no faces:
    surfaces with control points (n_u, n_v, 3), curves (n, 3), Euclidean, with their weights.

    OpenCASCADE runs in a child process (see ``_occ_reader.py``), so a file that crashes it,
    hangs it (``timeout`` seconds; by default :func:`read_timeout` of the file's size) or makes
    it allocate more than :func:`reader_memory` gives a FileFormatError here.
    """
    require_ocp(f"Reading {kind.upper()}")
    return read_in_worker(path, kind, timeout)
