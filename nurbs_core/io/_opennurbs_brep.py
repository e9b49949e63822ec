"""An openNURBS ``ON_Brep`` in openNURBS's binary archive format, so rhino3dm can decode it.

rhino3dm has no API to build B-rep topology: its ``Brep`` offers only ``CreateFrom*`` factories
(one face per surface), its vertex/edge/face lists are read-only and it has no Join. It does
decode any openNURBS object from the bytes ``ON_BinaryArchive::WriteObject`` writes
(``rhino3dm.CommonObject.Decode``, base64 in a dict), and openNURBS itself then validates it and
writes it to .3dm files. This module writes those bytes for a B-rep of untrimmed NURBS faces,
following ``ON_Brep::Write`` and friends (``opennurbs_brep_io.cpp``, ``opennurbs_archive.cpp``)
for 3dm archive version 60 (8-byte chunk lengths):

* a chunk is ``typecode (u32) + length (i64) + data [+ CRC32]``; chunks whose typecode has the
  ``TCODE_CRC`` bit end with the zlib CRC-32 of their own data (nested chunks excluded); the
  length counts the data and the CRC;
* a polymorphic object is a class chunk holding a class-UUID chunk, a class-data chunk and a
  short end chunk;
* openNURBS knot vectors omit the first and last knot of the full (n + p + 1,) vector.

Everything is little-endian; ints are 32-bit, reals float64.
"""

from __future__ import annotations

import base64
import struct
import uuid
import zlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, SupportsInt

import numpy as np
from numpy.typing import ArrayLike

ARCHIVE_VERSION = 60

TCODE_SHORT = 0x80000000
TCODE_CRC = 0x8000
TCODE_ANONYMOUS_CHUNK = 0x40000000 | TCODE_CRC
TCODE_OPENNURBS_CLASS = 0x00020000 | 0x7FFA
TCODE_OPENNURBS_CLASS_UUID = 0x00020000 | TCODE_CRC | 0x7FFB
TCODE_OPENNURBS_CLASS_DATA = 0x00020000 | TCODE_CRC | 0x7FFC
TCODE_OPENNURBS_CLASS_END = 0x00020000 | TCODE_SHORT | 0x7FFF

BREP_CLASS = uuid.UUID("60B5DBC5-E660-11d3-BFE4-0010830122F0")
NURBS_CURVE_CLASS = uuid.UUID("4ED7D4DD-E947-11d3-BFE5-0010830122F0")
NURBS_SURFACE_CLASS = uuid.UUID("4ED7D4DE-E947-11d3-BFE5-0010830122F0")

#: ON_BrepTrim::TYPE, ON_BrepLoop::TYPE and ON_Surface::ISO values used here
TRIM_BOUNDARY, TRIM_MATED = 1, 2
LOOP_OUTER, LOOP_INNER = 1, 2
ISO_NONE, ISO_W, ISO_S, ISO_E, ISO_N = 0, 3, 4, 5, 6

#: ON_BoundingBox's default (empty) box, written where openNURBS writes it
_EMPTY_BOX = (1.0, 0.0, 0.0, -1.0, 0.0, 0.0)


@dataclass
class Nurbs:
    """A non-rational NURBS curve (control (n, d)) or surface (control (n_u, n_v, 3)) with
    full knot vectors: ``knots`` (n + p + 1,) for a curve, ``(knots_u, knots_v)`` for a surface."""

    control: np.ndarray
    degrees: tuple[int, ...]
    knots: tuple[np.ndarray, ...]


@dataclass
class Edge:
    curve: int  # index into BrepTopology.curves_3d
    vertices: tuple[int, int]
    trims: list[int] = field(default_factory=list)
    domain: tuple[float, float] = (0.0, 1.0)
    #: how far the 3-D curve may lie from the trims' curves on the surface (0: exact)
    tolerance: float = 0.0


@dataclass
class Trim:
    curve: int  # index into BrepTopology.curves_2d
    edge: int
    vertices: tuple[int, int]
    reversed_3d: bool  # the trim runs against its edge
    kind: int  # TRIM_BOUNDARY or TRIM_MATED
    iso: int  # ISO_* side of the surface domain
    loop: int
    domain: tuple[float, float] = (0.0, 1.0)


@dataclass
class BrepTopology:
    """The arrays of an ON_Brep (all indices 0-based into these lists). Face f is untrimmed
    surface f with the one outer loop f; ``reversed_faces``: every face's normal is the
    opposite of its surface's."""

    curves_2d: list[Nurbs]
    curves_3d: list[Nurbs]
    surfaces: list[Nurbs]
    vertex_points: np.ndarray  # (V, 3)
    vertex_edges: list[list[int]]
    edges: list[Edge]
    trims: list[Trim]
    loops: list[tuple[list[int], int]]  # (trim indices, face index)
    box: tuple[np.ndarray, np.ndarray]  # min (3,), max (3,)
    reversed_faces: bool = False
    #: LOOP_OUTER / LOOP_INNER per loop (default: all outer) and each face's loops (default:
    #: face f has loop f), for trimmed faces with holes
    loop_kinds: list[int] | None = None
    face_loops: list[list[int]] | None = None


class _Chunk:
    """A chunk being built: own data bytes interleaved with nested chunks."""

    def __init__(self, typecode: int) -> None:
        self.typecode = typecode
        self.parts: list[bytes | _Chunk] = []

    def pack(self, fmt: str, *values: Any) -> None:
        self.parts.append(struct.pack("<" + fmt, *values))

    def ints(self, values: Iterable[SupportsInt]) -> None:
        numbers = [int(v) for v in values]
        self.pack(f"{len(numbers)}i", *numbers)

    def doubles(self, values: ArrayLike) -> None:
        numbers = [float(v) for v in np.ravel(values)]
        self.pack(f"{len(numbers)}d", *numbers)

    def int_array(self, values: Sequence[int]) -> None:
        """ON_BinaryArchive::WriteArray of ints: the count, then the values."""
        self.ints([len(values), *values])

    def chunk(self, typecode: int) -> _Chunk:
        child = _Chunk(typecode)
        self.parts.append(child)
        return child

    def to_bytes(self) -> bytes:
        if self.typecode & TCODE_SHORT:
            return struct.pack("<Iq", self.typecode, 0)
        own = b"".join(p for p in self.parts if isinstance(p, bytes))
        body = b"".join(p if isinstance(p, bytes) else p.to_bytes() for p in self.parts)
        if self.typecode & TCODE_CRC:
            body += struct.pack("<I", zlib.crc32(own))
        return struct.pack("<Iq", self.typecode, len(body)) + body


def _object(parent: _Chunk, class_id: uuid.UUID) -> _Chunk:
    """Write an object's class header into ``parent``; returns its class-data chunk."""
    wrapper = parent.chunk(TCODE_OPENNURBS_CLASS)
    wrapper.chunk(TCODE_OPENNURBS_CLASS_UUID).parts.append(class_id.bytes_le)
    data = wrapper.chunk(TCODE_OPENNURBS_CLASS_DATA)
    wrapper.chunk(TCODE_OPENNURBS_CLASS_END)
    return data


def _write_curve(data: _Chunk, curve: Nurbs) -> None:
    """ON_NurbsCurve::Write, chunk version 1.1."""
    control = np.asarray(curve.control, np.float64)
    (degree,), (knots,) = curve.degrees, curve.knots
    data.pack("B", 0x11)
    data.ints([control.shape[1], 0, degree + 1, len(control), 0, 0])
    data.doubles(_EMPTY_BOX)
    data.ints([len(knots) - 2])
    data.doubles(knots[1:-1])
    data.ints([len(control)])
    data.doubles(control)
    data.pack("B", 0)  # SubD-friendly tag


def _write_surface(data: _Chunk, surface: Nurbs) -> None:
    """ON_NurbsSurface::Write, chunk version 1.0 (CVs u-major)."""
    control = np.asarray(surface.control, np.float64)
    n_u, n_v = control.shape[:2]
    data.pack("B", 0x10)
    data.ints([3, 0, surface.degrees[0] + 1, surface.degrees[1] + 1, n_u, n_v, 0, 0])
    data.doubles(_EMPTY_BOX)
    for knots in surface.knots:
        data.ints([len(knots) - 2])
        data.doubles(knots[1:-1])
    data.ints([n_u * n_v])
    data.doubles(control)


def _object_array(parent: _Chunk, items: list[Nurbs], class_id: uuid.UUID,
                  write: Callable[[_Chunk, Nurbs], None]) -> None:
    """ON_CurveArray / ON_SurfaceArray::Write."""
    chunk = parent.chunk(TCODE_ANONYMOUS_CHUNK)
    chunk.pack("B", 0x10)
    chunk.ints([len(items)])
    for item in items:
        chunk.ints([1])
        write(_object(chunk, class_id), item)


def _component_array(parent: _Chunk, version: int, count: int) -> _Chunk:
    chunk = parent.chunk(TCODE_ANONYMOUS_CHUNK)
    chunk.pack("B", version)
    chunk.ints([count])
    return chunk


def _write_brep(data: _Chunk, brep: BrepTopology) -> None:
    """ON_Brep::Write, chunk version 3.3."""
    data.pack("B", 0x33)
    _object_array(data, brep.curves_2d, NURBS_CURVE_CLASS, _write_curve)
    _object_array(data, brep.curves_3d, NURBS_CURVE_CLASS, _write_curve)
    _object_array(data, brep.surfaces, NURBS_SURFACE_CLASS, _write_surface)
    chunk = _component_array(data, 0x10, len(brep.vertex_points))
    for index, (point, edges) in enumerate(zip(brep.vertex_points, brep.vertex_edges)):
        chunk.ints([index])
        chunk.doubles(point)
        chunk.int_array(edges)
        chunk.doubles([0.0])  # tolerance: exact
    chunk = _component_array(data, 0x10, len(brep.edges))
    for index, edge in enumerate(brep.edges):
        chunk.ints([index, edge.curve, 0])  # not reversed
        chunk.doubles(edge.domain)  # proxy-curve domain
        chunk.ints(edge.vertices)
        chunk.int_array(edge.trims)
        chunk.doubles([edge.tolerance, *edge.domain])  # tolerance, domain
    chunk = _component_array(data, 0x10, len(brep.trims))
    for index, trim in enumerate(brep.trims):
        chunk.ints([index, trim.curve])
        chunk.doubles(trim.domain)
        chunk.ints([trim.edge, *trim.vertices, int(trim.reversed_3d), trim.kind, trim.iso,
                    trim.loop])
        chunk.doubles([0.0, 0.0, *trim.domain])  # tolerances, domain
        chunk.parts.append(bytes(32))  # proxy curve not reversed; reserved
        chunk.doubles([0.0, 0.0])  # legacy tolerances
    chunk = _component_array(data, 0x10, len(brep.loops))
    for index, (trims, face) in enumerate(brep.loops):
        chunk.ints([index])
        chunk.int_array(trims)
        chunk.ints([LOOP_OUTER if brep.loop_kinds is None else brep.loop_kinds[index], face])
    chunk = _component_array(data, 0x11, len(brep.surfaces))
    for index in range(len(brep.surfaces)):
        chunk.ints([index])
        chunk.int_array([index] if brep.face_loops is None else brep.face_loops[index])
        chunk.ints([index, int(brep.reversed_faces), 0])  # surface, reversed, material channel
    for _ in brep.surfaces:
        chunk.parts.append(bytes(16))  # nil face UUIDs
    data.doubles(np.concatenate(brep.box))
    for _ in ("render meshes", "analysis meshes"):
        data.chunk(TCODE_ANONYMOUS_CHUNK).parts.append(bytes(len(brep.surfaces)))
    data.ints([0])  # solidity unset: openNURBS works it out
    region = data.chunk(TCODE_ANONYMOUS_CHUNK)
    region.ints([1, 1])  # anonymous chunk version 1.1
    region.pack("B", 0)  # no region topology


def encode_brep(brep: BrepTopology, opennurbs_version: int) -> dict[str, Any]:
    """The dictionary ``rhino3dm.CommonObject.Decode`` takes, holding ``brep``."""
    root = _Chunk(0)
    _write_brep(_object(root, BREP_CLASS), brep)
    (wrapper,) = root.parts
    assert isinstance(wrapper, _Chunk)  # _object added the class chunk, nothing else
    return {"version": 10000, "archive3dm": ARCHIVE_VERSION, "opennurbs": opennurbs_version,
            "data": base64.b64encode(wrapper.to_bytes()).decode("ascii")}
