"""``load`` / ``load_any`` / ``save``: one entry point per direction, dispatched on the suffix."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any, TypeAlias, TypeGuard, cast

from nurbs_core.io.cloud import PointCloud
from nurbs_core.io.errors import FileFormatError, StrPath
from nurbs_core.io.points import POINT_CLOUD_SUFFIXES, _check_file, load_points, suffix_of
from nurbs_core.io.suffixes import EXPORT_SUFFIXES, NETWORK_SUFFIXES, NURBS_SUFFIXES

if TYPE_CHECKING:
    from nurbs_core.geometry import NurbsCurve, NurbsSurface
    from nurbs_core.io.geometry_io import GeometryInput
    from nurbs_core.patches.network import PatchNetwork
    from nurbs_core.trim.value import TrimmedSurface

#: One file for :func:`save_all`: (geometry or a patch network, path, options for the writer).
SaveJob: TypeAlias = ("tuple[GeometryInput | PatchNetwork | TrimmedSurface, StrPath, "
                      "Mapping[str, Any] | None]")



def _load_json(path: StrPath) -> list[NurbsCurve | NurbsSurface]:
    from nurbs_core.io import geomdl_json, json_format

    document = json_format.read_json_file(path)
    if isinstance(document, dict):
        if document.get("format") == json_format.FORMAT_NAME:
            geometry, metadata = json_format.read_document(path, document)
            if "units" in metadata:  # the document's length unit (save(..., units=)) per item
                for item in geometry:
                    item.metadata = {"units": metadata["units"], **item.metadata}
            return geometry
        if document.get("format") == json_format.SHARED_FORMAT_NAME or "ctrlpts" in document:
            return json_format.read_shared_json(path, document)
        if geomdl_json.is_geomdl_document(document):
            return geomdl_json.read_geomdl_json(path, document)
        from nurbs_core.io import network_io

        if document.get("format") == network_io.NETWORK_FORMAT:
            # a patch network (what nurbs-fit --patches and the app's Patches mode write): its
            # patches as surfaces; read_network gives the network itself
            network, metadata = network_io.read_network_with_metadata(path)
            surfaces: list[NurbsCurve | NurbsSurface] = []
            for number, surface in enumerate(network.surfaces()):
                surface.metadata = {**metadata, "name": f"patch {number}", "network": True}
                surfaces.append(surface)
            return surfaces
    found = "" if isinstance(document, dict) else \
        f" (the file holds {json_format.json_kind(document)}, not an object)"
    raise FileFormatError(path, f"unrecognised JSON{found}: expected a nurbs-studio document "
                                "(\"format\": \"nurbs-studio\"), a patch network (\"format\": "
                                "\"nurbs-studio-network-v1\"), a nurbs-surface-json-v1 surface "
                                "or a geomdl export ({\"shape\": {\"data\": ...}})")


def load(path: StrPath) -> list[NurbsCurve | NurbsSurface]:
    """Read NURBS geometry: a list of NurbsCurve / NurbsSurface (float64), one per item.

    Curves have control points (n, 2) or (n, 3), surfaces (n_u, n_v, 3) (Euclidean), with
    weights (n,) / (n_u, n_v) and full knot vectors.

    .3dm (rhino3dm), .json (ours, geomdl, nurbs-surface-json-v1; sniffed), .dat/.smesh,
    .step/.stp/.iges/.igs/.brep (OCP extra; a solid's faces as their untrimmed surfaces). Each
    item carries a ``metadata`` dict attribute.
    """
    suffix = suffix_of(path)
    if suffix not in NURBS_SUFFIXES:
        raise FileFormatError(path, f"unknown NURBS suffix {suffix!r}; supported: "
                                    f"{', '.join(NURBS_SUFFIXES)}")
    _check_file(path)
    if suffix == ".3dm":
        from nurbs_core.io.rhino import read_3dm

        return read_3dm(path)
    if suffix == ".json":
        return _load_json(path)
    if suffix in (".dat", ".smesh"):
        from nurbs_core.io.smesh import read_smesh

        return read_smesh(path)
    from nurbs_core.io.cad import read_cad
    from nurbs_core.io.cad_shape import SHAPE_KINDS

    return read_cad(path, SHAPE_KINDS[suffix])


def load_any(path: StrPath, **point_options: Any) -> PointCloud | list[NurbsCurve | NurbsSurface]:
    """A PointCloud for point/mesh formats, a list of geometry for NURBS formats.

    The cloud's points are (N, 3) float64; the geometry is what :func:`load` returns.

    ``.ply`` is a point cloud; ``.json`` and ``.dat`` are NURBS; keyword options go to
    :func:`load_points`.
    """
    suffix = suffix_of(path)
    if suffix in NURBS_SUFFIXES:
        return load(path)
    if suffix in POINT_CLOUD_SUFFIXES:
        return load_points(path, **point_options)
    raise FileFormatError(path, f"unknown suffix {suffix!r}; supported: "
                                f"{', '.join(sorted(set(NURBS_SUFFIXES + POINT_CLOUD_SUFFIXES)))}")


def save(geometry_or_list: GeometryInput | PatchNetwork | TrimmedSurface, path: StrPath,
         **options: Any) -> None:
    """Write one NurbsCurve / NurbsSurface or a list of them; the suffix picks the format.

    Curves have control points (*B, n, d) with d 2 or 3, surfaces (*B, n_u, n_v, 3); a batch
    shape B gives one item per entry.

    Option ``units`` (:mod:`nurbs_core.io.units`, any format): the length unit .3dm, STEP and
    IGES declare and JSON's metadata holds (the coordinates are never scaled).

    .3dm (rhino3dm; option ``version``), .step/.stp and .iges/.igs (OCP extra), .json (ours,
    lossless; option ``metadata`` for the document, ``indent``), .obj/.stl/.ply/.glb (surfaces
    tessellated on a uniform grid; option ``resolution``, int or (r_u, r_v), default 64), .csv
    (control points and weights), .dat (smesh, one surface). Batched geometry is split into
    one item per batch entry. A :class:`~nurbs_core.patches.network.PatchNetwork` is written
    whole by :func:`nurbs_core.io.network_io.write_network` (one joined B-rep / sewn shell); a
    :class:`~nurbs_core.trim.value.TrimmedSurface` as one trimmed face
    (:mod:`nurbs_core.io.trimmed_io`: .json, .step, .iges, .3dm, meshes).

    The write is atomic: the file is written next to ``path`` and replaces it only once complete
    and flushed, so a failed save (full disk, an exception, Ctrl-C) leaves an existing file as
    it was.
    """
    save_all([(geometry_or_list, path, options)])


def save_all(jobs: Iterable[SaveJob]) -> None:
    """Write several files all-or-nothing: ``jobs`` is a sequence of (geometry, path, options
    dict). Every suffix is checked first; the files are written to temporaries and replace
    their targets only when all of them were written (:func:`nurbs_core.atomic.atomic_paths`).
    """
    from nurbs_core.atomic import atomic_paths

    checked = [(geometry, path, dict(options or {})) for geometry, path, options in jobs]
    for geometry, path, _ in checked:
        check_save_suffix(geometry, path)
    with atomic_paths([path for _, path, _ in checked]) as temporaries:
        for (geometry, path, options), temporary in zip(checked, temporaries, strict=True):
            try:
                _write(geometry, temporary, suffix_of(path), **options)
            except FileFormatError as exc:  # name the target, not the temporary file
                raise FileFormatError(path, exc.problem, exc.line) from None


def is_network(geometry: object) -> TypeGuard[PatchNetwork]:
    """True when ``geometry`` is a :class:`~nurbs_core.patches.network.PatchNetwork`."""
    from nurbs_core.patches.network import PatchNetwork

    return isinstance(geometry, PatchNetwork)


def is_trimmed(geometry: object) -> TypeGuard[TrimmedSurface]:
    """True when ``geometry`` is a :class:`~nurbs_core.trim.value.TrimmedSurface`."""
    from nurbs_core.trim.value import TrimmedSurface

    return isinstance(geometry, TrimmedSurface)


def check_save_suffix(geometry: object, path: StrPath) -> None:
    """FileFormatError unless ``save`` can write ``geometry`` (geometry, or a patch network) in
    the format of ``path``'s suffix."""
    suffix = suffix_of(path)
    if is_trimmed(geometry):
        from nurbs_core.io.trimmed_io import TRIMMED_SUFFIXES

        if suffix not in TRIMMED_SUFFIXES:
            raise FileFormatError(path, f"cannot save a trimmed surface as {suffix!r}; "
                                        f"supported: {', '.join(TRIMMED_SUFFIXES)}")
    elif geometry is not None and is_network(geometry):
        if suffix not in NETWORK_SUFFIXES:
            raise FileFormatError(path, f"cannot save a patch network as {suffix!r}; supported: "
                                        f"{', '.join(NETWORK_SUFFIXES)}")
    elif suffix not in EXPORT_SUFFIXES:
        raise FileFormatError(path, f"cannot save geometry as {suffix!r}; supported: "
                                    f"{', '.join(EXPORT_SUFFIXES)}")


def _write(geometry_or_list: GeometryInput | PatchNetwork | TrimmedSurface, path: StrPath, suffix: str,
           **options: Any) -> None:
    """Write to ``path`` (a temporary file) in the format of ``suffix``."""
    if is_trimmed(geometry_or_list):
        from nurbs_core.io.trimmed_io import write_trimmed_file

        write_trimmed_file(geometry_or_list, path, suffix, **options)
        return
    if is_network(geometry_or_list):
        from nurbs_core.io.network_io import write_network_file

        write_network_file(geometry_or_list, path, suffix, **options)
        return
    geometry = cast("GeometryInput", geometry_or_list)  # not a network: curves and surfaces
    # the model's length unit: declared by the formats that carry one, ignored by the others
    units = options.pop("units", None)
    if suffix == ".3dm":
        from nurbs_core.io.rhino import write_3dm

        write_3dm(geometry, path, units=units, **options)
    elif suffix in (".step", ".stp"):
        from nurbs_core.io.cad import write_step

        write_step(geometry, path, units=units, **options)
    elif suffix in (".iges", ".igs"):
        from nurbs_core.io.cad import write_iges

        write_iges(geometry, path, units=units, **options)
    elif suffix == ".json":
        from nurbs_core.io.json_format import write_json
        from nurbs_core.io.units import units_metadata

        options["metadata"] = units_metadata(options.get("metadata"), units)
        write_json(geometry, path, **options)
    elif suffix in (".obj", ".stl", ".ply", ".glb"):
        from nurbs_core.io.tessellate import write_mesh

        write_mesh(geometry, path, **options)
    elif suffix == ".csv":
        from nurbs_core.io.control_points_csv import write_control_points_csv

        write_control_points_csv(geometry, path, **options)
    elif suffix == ".dat":
        from nurbs_core.io.smesh import write_smesh

        write_smesh(geometry, path, **options)
    else:  # check_save_suffix ran first
        raise FileFormatError(path, f"cannot save geometry as {suffix!r}")
