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
import io
import json
import os
import select
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

from nurbs_core.io.errors import FileFormatError, require_ocp
from nurbs_core.io.geometry_io import as_geometry_list, make_curve, make_surface, numpy_of

STEP_SUFFIXES = (".step", ".stp")
IGES_SUFFIXES = (".iges", ".igs")


def distinct_knots(knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full knot vector (m,) -> (distinct values, multiplicities), exact (no tolerance)."""
    values, counts = np.unique(np.asarray(knots, dtype=np.float64), return_counts=True)
    return values, counts


_QUIETED = False


def quiet_occ() -> None:
    """Stop OpenCASCADE's default messenger from printing transfer statistics to stdout."""
    global _QUIETED
    if _QUIETED:
        return
    from OCP.Message import Message, Message_PrinterOStream

    Message.DefaultMessenger_s().RemovePrinters(Message_PrinterOStream.get_type_descriptor_s())
    _QUIETED = True


def _array1_double(values):
    from OCP.collections import Array1_double

    array = Array1_double(1, len(values))
    for k, value in enumerate(values, start=1):
        array.SetValue(k, float(value))
    return array


def _array1_int(values):
    from OCP.collections import Array1_int

    array = Array1_int(1, len(values))
    for k, value in enumerate(values, start=1):
        array.SetValue(k, int(value))
    return array


def occ_surface(data: dict):
    """A ``Geom_BSplineSurface`` from a surface's ``numpy()`` dict."""
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


def occ_curve(data: dict):
    """A ``Geom_BSplineCurve`` from a curve's ``numpy()`` dict (2-D curves get z = 0)."""
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


def _compound(items):
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace
    from OCP.TopoDS import TopoDS_Compound

    builder = BRep_Builder()
    compound = TopoDS_Compound()
    builder.MakeCompound(compound)
    for index, item in enumerate(items):
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


def step_bytes(shape, path) -> bytes:
    """The STEP (AP214, millimetres) text of an OCP shape, every real written as %.16E (17
    significant digits, exact for float64); ``path`` names the file in errors (OSError).

    STEPControl_Writer's own Write keeps 13 significant digits (a few 1e-9 off at coordinates
    of 1e4), so the model is printed here with a finer FloatWriter.
    """
    require_ocp("Writing STEP")
    quiet_occ()
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.Interface import Interface_Static
    from OCP.STEPControl import STEPControl_StepModelType, STEPControl_Writer
    from OCP.StepData import StepData_StepWriter

    writer = STEPControl_Writer()
    Interface_Static.SetCVal_s("write.step.unit", "MM")
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


def iges_bytes(shape, path, brep: bool = False) -> bytes:
    """The IGES (millimetres) text of an OCP shape, every real written as %.16E (17 significant
    digits, exact for float64); ``path`` names the file in errors (OSError). Faces are trimmed
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

    writer = IGESControl_Writer("MM", 1 if brep else 0)
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


def write_step(geometry_or_list, path) -> None:
    """STEP (AP214): the geometry as one compound of faces and edges (see :func:`step_bytes`)."""
    require_ocp("Writing STEP")
    data = step_bytes(_compound(as_geometry_list(geometry_or_list)), path)
    with open(path, "wb") as handle:
        handle.write(data)


def write_iges(geometry_or_list, path) -> None:
    """IGES: the geometry as trimmed surfaces and curves (see :func:`iges_bytes`)."""
    require_ocp("Writing IGES")
    data = iges_bytes(_compound(as_geometry_list(geometry_or_list)), path)
    with open(path, "wb") as handle:
        handle.write(data)


READ_TIMEOUT_SECONDS = 600.0


class _ReaderProcess:
    """The long-lived child running ``_occ_reader.py`` (OpenCASCADE may segfault on damaged
    files: a crash ends the child, not the program, and the next read starts a new one)."""

    def __init__(self):
        self._process: subprocess.Popen | None = None
        self._lock = threading.Lock()

    def _start(self) -> subprocess.Popen:
        script = Path(__file__).with_name("_occ_reader.py")
        # -I: the child sees neither this folder nor PYTHONPATH, only the installed packages
        return subprocess.Popen([sys.executable, "-I", str(script)], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                bufsize=1)

    def request(self, path: str, kind: str, output: str, timeout: float) -> dict:
        with self._lock:
            if self._process is None or self._process.poll() is not None:
                self._process = self._start()
            process = self._process
            try:
                process.stdin.write(json.dumps({"path": path, "kind": kind,
                                                "output": output}) + "\n")
                process.stdin.flush()
            except BrokenPipeError:
                process.wait()
                self._process = None
                return {"ok": False, "crashed": process.returncode}
            ready, _, _ = select.select([process.stdout], [], [], timeout)
            if not ready:
                process.kill()
                process.wait()
                self._process = None
                return {"ok": False, "error": f"reading took longer than {timeout:g} s"}
            line = process.stdout.readline()
            if not line:  # the child died while reading this file
                process.wait()
                self._process = None
                return {"ok": False, "crashed": process.returncode}
            return json.loads(line)

    def close(self) -> None:
        with self._lock:
            if self._process is not None and self._process.poll() is None:
                self._process.stdin.close()
                try:
                    self._process.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    self._process.kill()
                    self._process.wait()
            self._process = None


_READER = _ReaderProcess()
atexit.register(_READER.close)


def read_cad(path, kind: str, timeout: float = READ_TIMEOUT_SECONDS) -> list:
    """All surfaces (untrimmed) of a STEP or IGES file; its curves when it has no faces.

    OpenCASCADE runs in a child process (see ``_occ_reader.py``), so a file that crashes it
    gives a FileFormatError here.
    """
    require_ocp(f"Reading {kind.upper()}")
    with open(path, "rb") as handle:
        if not handle.read(1):
            raise FileFormatError(path, "the file is empty")
    with tempfile.TemporaryDirectory(prefix="nurbs_io_") as folder:
        output = os.path.join(folder, "items.npz")
        reply = _READER.request(os.path.abspath(path), kind, output, timeout)
        if "crashed" in reply:
            raise FileFormatError(path, f"OpenCASCADE crashed reading this {kind.upper()} file "
                                        f"(exit status {reply['crashed']}): it is damaged or "
                                        "uses something OpenCASCADE cannot handle")
        if not reply["ok"]:
            raise FileFormatError(path, reply["error"])
        with np.load(output, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    result = []
    for k in range(reply["count"]):
        degrees = arrays[f"degrees_{k}"]
        if str(arrays[f"kind_{k}"]) == "surface":
            result.append(make_surface(path, arrays[f"control_{k}"], arrays[f"weights_{k}"],
                                       arrays[f"knots_u_{k}"], arrays[f"knots_v_{k}"],
                                       int(degrees[0]), int(degrees[1]), what=f"face {k}"))
        else:
            result.append(make_curve(path, arrays[f"control_{k}"], arrays[f"weights_{k}"],
                                     arrays[f"knots_{k}"], int(degrees[0]), what=f"edge {k}"))
    return result
