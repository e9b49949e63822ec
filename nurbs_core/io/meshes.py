"""Triangle meshes (OBJ, STL, OFF, GLB/GLTF, PLY with faces) as point clouds, via trimesh.

``mesh_mode="vertices"`` returns the file's vertices (STL's per-triangle copies merged);
``mesh_mode="sample"`` draws ``sample_count`` points uniformly over the surface area (trimesh's
area-weighted triangle sampling) with the face normal of each sample as ``normals`` and the
face each came from as ``face_index``. A file with no faces (a point cloud stored as OBJ or PLY)
gives its vertices in either mode.

trimesh trusts the counts and lengths a file announces, so they are checked here first, against
the file size: the triangle count of a binary STL, the counts line of an OFF file, the element
counts and list lengths of a PLY file, and every buffer, buffer view and accessor of a glTF /
GLB document (zero-filled accessors and instanced meshes against the decompression limit;
external buffers only as regular files in the glTF's folder, read up to their declared
length). Materials and textures are never loaded. Whatever trimesh raises becomes a
FileFormatError naming the file.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import stat
import struct
import urllib.parse
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from nurbs_core.io.cloud import PointCloud, check_points
from nurbs_core.io.errors import FileFormatError, StrPath

if TYPE_CHECKING:
    import trimesh
    from trimesh.parent import Geometry as TrimeshGeometry
from nurbs_core.io.limits import check_claimed_size, check_decompressed_size, format_size

MESH_MODES = ("vertices", "sample")

_GLB_MAGIC = b"glTF"
_GLB_JSON, _GLB_BIN = 0x4E4F534A, 0x004E4942
# keyed by whatever a glTF document holds there (looked up before it is known to be an int / str)
_GLTF_COMPONENT_BYTES: dict[object, int] = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_GLTF_TYPE_SIZE: dict[object, int] = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4,
                                      "MAT3": 9, "MAT4": 16}
#: OFF and STL headers are looked for in the first bytes of the file.
_HEAD_BYTES = 1 << 16
#: trimesh merges a glTF scene one placed primitive at a time (about half a millisecond each)
#: and walks every node: beyond these a file cannot be read in seconds.
_MAX_GLTF_PLACEMENTS = 10_000
_MAX_GLTF_NODES = 200_000


def _natural(path: StrPath, value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise FileFormatError(path, f"{what} must be a non-negative integer, got {value!r}"[:300])
    return value


def _index(path: StrPath, value: object, length: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < length:
        raise FileFormatError(path, f"{what} must be an index below {length}, got {value!r}"[:300])
    return value


def _indices(path: StrPath, owner: dict[str, Any], key: str, length: int, what: str, item: str) -> list[int]:
    """``owner[key]`` (default empty): a list of indices below ``length``."""
    values = owner.get(key, [])
    if not isinstance(values, list):
        raise FileFormatError(path, f"{what}: {key} must be a list")
    return [_index(path, value, length, f"{what}: {item}") for value in values]


def _objects(path: StrPath, document: dict[str, Any], key: str) -> list[dict[str, Any]]:
    value = document.get(key, [])
    if not isinstance(value, list) or not all(isinstance(item, dict) for item in value):
        raise FileFormatError(path, f"glTF '{key}' must be a list of objects, got "
                                    f"{type(value).__name__}")
    return value


def _external_buffer(path: StrPath, uri: str, length: int, what: str) -> bytes:
    """The first ``length`` bytes of a buffer file next to the glTF: a relative path inside its
    folder to a regular file (no URL, no device, no file elsewhere on the system)."""
    parsed = urllib.parse.urlparse(uri)
    relative = urllib.parse.unquote(parsed.path)
    if parsed.scheme or parsed.netloc or os.path.isabs(relative):
        raise FileFormatError(path, f"{what}: only embedded data: URIs and files next to the "
                                    f"glTF are read, not {uri[:200]!r}")
    folder = os.path.realpath(os.path.dirname(os.path.abspath(os.fspath(path))))
    target = os.path.realpath(os.path.join(folder, relative))
    if os.path.commonpath([folder, target]) != folder:
        raise FileFormatError(path, f"{what}: {uri[:200]!r} points outside the glTF's folder")
    try:
        info = os.stat(target)
    except OSError:
        raise FileFormatError(path, f"{what}: the buffer file {uri[:200]!r} does not exist") \
            from None
    if not stat.S_ISREG(info.st_mode):
        raise FileFormatError(path, f"{what}: {uri[:200]!r} is not a regular file")
    if info.st_size < length:
        raise FileFormatError(path, f"{what} declares {length} bytes, but {uri[:200]!r} has "
                                    f"only {info.st_size}")
    with open(target, "rb") as handle:
        return handle.read(length)


def _data_uri_bytes(uri: str) -> int:
    """The bytes a data: URI holds (exact for valid base64)."""
    comma = uri.find(",")
    payload = uri[comma + 1:]
    if ";base64" in uri[:comma]:
        return len(payload.rstrip("=")) * 3 // 4
    return len(urllib.parse.unquote(payload))


def _check_gltf(path: StrPath, document: object, chunks: list[int]) -> dict[str, bytes]:
    """Check a glTF document's layout against the data present; return the external buffers
    (uri -> bytes, read up to their declared length) for trimesh's resolver."""
    if not isinstance(document, dict):
        raise FileFormatError(path, "the glTF JSON is not an object")
    file_size = os.path.getsize(path)
    buffers, views, accessors = (_objects(path, document, key)
                                 for key in ("buffers", "bufferViews", "accessors"))
    meshes, nodes = _objects(path, document, "meshes"), _objects(path, document, "nodes")
    sizes: list[int] = []
    external: dict[str, bytes] = {}
    unnamed = iter(chunks)
    for k, buffer in enumerate(buffers):
        length = _natural(path, buffer.get("byteLength"), f"buffer {k}: byteLength")
        uri = buffer.get("uri")
        if uri is None:
            present = next(unnamed, None)
            if present is None:
                raise FileFormatError(path, f"buffer {k} has no uri and no binary chunk holds "
                                            "its data")
        elif not isinstance(uri, str):
            raise FileFormatError(path, f"buffer {k}: uri must be a string")
        elif uri.startswith("data:"):
            present = _data_uri_bytes(uri)
        else:
            external[uri] = _external_buffer(path, uri, length, f"buffer {k}")
            present = length
        if length > present:
            raise FileFormatError(path, f"buffer {k} declares {length} bytes, but its data has "
                                        f"only {present}")
        sizes.append(length)
    view_sizes: list[int] = []
    for k, view in enumerate(views):
        owner = _index(path, view.get("buffer"), len(buffers), f"buffer view {k}: buffer")
        offset = _natural(path, view.get("byteOffset", 0), f"buffer view {k}: byteOffset")
        length = _natural(path, view.get("byteLength"), f"buffer view {k}: byteLength")
        if offset + length > sizes[owner]:
            raise FileFormatError(path, f"buffer view {k} (bytes {offset} to {offset + length}) "
                                        f"runs past the end of buffer {owner} "
                                        f"({sizes[owner]} bytes)")
        if view.get("byteStride") is not None and \
                _natural(path, view["byteStride"], f"buffer view {k}: byteStride") == 0:
            raise FileFormatError(path, f"buffer view {k}: byteStride must be positive")
        view_sizes.append(length)
    zeros = 0
    for k, accessor in enumerate(accessors):
        count = _natural(path, accessor.get("count"), f"accessor {k}: count")
        component = accessor.get("componentType")
        kind = accessor.get("type")
        if component not in _GLTF_COMPONENT_BYTES or kind not in _GLTF_TYPE_SIZE:
            raise FileFormatError(path, f"accessor {k}: unknown componentType {component!r} or "
                                        f"type {kind!r}"[:300])
        element = _GLTF_COMPONENT_BYTES[component] * _GLTF_TYPE_SIZE[kind]
        offset = _natural(path, accessor.get("byteOffset", 0), f"accessor {k}: byteOffset")
        if "bufferView" in accessor:
            view_index = _index(path, accessor["bufferView"], len(views), f"accessor {k}: bufferView")
            stride = views[view_index].get("byteStride") or element
            needed = offset + (count - 1) * stride + element if count else offset
            if needed > view_sizes[view_index]:
                raise FileFormatError(path, f"accessor {k} claims {count} items "
                                            f"({format_size(needed)}), but buffer view {view_index} "
                                            f"has only {format_size(view_sizes[view_index])}")
        else:
            zeros += count * element
        sparse = accessor.get("sparse")
        if sparse is not None:
            _check_sparse(path, k, sparse, count, element, views, view_sizes)
    check_decompressed_size(path, zeros, file_size, what="the accessors without data (zeros)")
    _check_scene(path, document, accessors, meshes, nodes, file_size)
    return external


def _check_sparse(path: StrPath, k: int, sparse: object, count: int, element: int,
                  views: list[dict[str, Any]], view_sizes: list[int]) -> None:
    if not isinstance(sparse, dict):
        raise FileFormatError(path, f"accessor {k}: sparse must be an object")
    changed = _natural(path, sparse.get("count"), f"accessor {k}: sparse count")
    if changed > count:
        raise FileFormatError(path, f"accessor {k}: sparse count {changed} is more than its "
                                    f"{count} items")
    parts: tuple[tuple[str, int | None], ...] = (("indices", None), ("values", element))
    for part, size in parts:
        block = sparse.get(part)
        if not isinstance(block, dict):
            raise FileFormatError(path, f"accessor {k}: sparse {part} must be an object")
        view = _index(path, block.get("bufferView"), len(views),
                      f"accessor {k}: sparse {part} bufferView")
        if size is None:
            size = _GLTF_COMPONENT_BYTES.get(block.get("componentType"), 0)
            if size == 0:
                raise FileFormatError(path, f"accessor {k}: unknown sparse index type")
        offset = _natural(path, block.get("byteOffset", 0), f"accessor {k}: sparse byteOffset")
        if offset + changed * size > view_sizes[view]:
            raise FileFormatError(path, f"accessor {k}: sparse {part} run past the end of buffer "
                                        f"view {view}")


def _check_scene(path: StrPath, document: dict[str, Any], accessors: list[dict[str, Any]],
                 meshes: list[dict[str, Any]], nodes: list[dict[str, Any]], file_size: int) -> None:
    """References between meshes, nodes and scenes; the nodes must form a forest (no cycles,
    one parent each) and the mesh data they instantiate must stay within the decompression
    limit (one mesh placed by many nodes is copied once per node)."""
    if len(nodes) > _MAX_GLTF_NODES:
        raise FileFormatError(path, f"the glTF scene has {len(nodes)} nodes, more than the "
                                    f"{_MAX_GLTF_NODES} that can be read in time")
    weights: list[int] = []
    parts: list[int] = []
    for k, mesh in enumerate(meshes):
        primitives = mesh.get("primitives", [])
        if not isinstance(primitives, list) or not all(isinstance(p, dict) for p in primitives):
            raise FileFormatError(path, f"mesh {k}: primitives must be a list of objects")
        weight = 0
        for primitive in primitives:
            attributes = primitive.get("attributes", {})
            if not isinstance(attributes, dict):
                raise FileFormatError(path, f"mesh {k}: attributes must be an object")
            for name, accessor in attributes.items():
                _index(path, accessor, len(accessors), f"mesh {k}: attribute {name}")
            if "POSITION" in attributes:
                weight += 24 * accessors[attributes["POSITION"]]["count"]
            if primitive.get("indices") is not None:
                index = _index(path, primitive["indices"], len(accessors), f"mesh {k}: indices")
                weight += 8 * accessors[index]["count"]
        weights.append(weight)
        parts.append(len(primitives))
    parent: dict[int, int] = {}
    instanced = placed = 0
    for k, node in enumerate(nodes):
        for child in _indices(path, node, "children", len(nodes), f"node {k}", "child"):
            if child == k or child in parent:
                raise FileFormatError(path, f"node {child} has two parents or is its own child: "
                                            "the node hierarchy is not a tree")
            parent[child] = k
        if node.get("mesh") is not None:
            mesh_index = _index(path, node["mesh"], len(meshes), f"node {k}: mesh")
            instanced += weights[mesh_index]
            placed += parts[mesh_index]
    settled: set[int] = set()
    for k in range(len(nodes)):  # with one parent each, a loop is the only way to fail a tree
        chain: set[int] = set()
        at = k
        while at in parent and at not in settled:
            if at in chain:
                raise FileFormatError(path, f"node {at} is its own ancestor: the node "
                                            "hierarchy has a cycle")
            chain.add(at)
            at = parent[at]
        settled |= chain
    for k, scene in enumerate(_objects(path, document, "scenes")):
        _indices(path, scene, "nodes", len(nodes), f"scene {k}", "node")
    placed = placed if nodes else sum(parts)
    if placed > _MAX_GLTF_PLACEMENTS:
        raise FileFormatError(path, f"the glTF scene places {placed} mesh primitives, more than "
                                    f"the {_MAX_GLTF_PLACEMENTS} that can be merged in time "
                                    "(split the file)")
    check_decompressed_size(path, instanced if nodes else sum(weights), file_size,
                            what="the meshes the glTF scene places")


def _check_glb(path: StrPath) -> dict[str, bytes]:
    size = os.path.getsize(path)
    with open(path, "rb") as handle:
        head = handle.read(20)
        if len(head) < 20 or head[:4] != _GLB_MAGIC:
            raise FileFormatError(path, "not a GLB file (no glTF magic at the start)")
        version, total, json_length, json_type = struct.unpack_from("<IIII", head, 4)
        if version != 2:
            raise FileFormatError(path, f"GLB version {version}: only glTF 2 is supported")
        if json_type != _GLB_JSON:
            raise FileFormatError(path, "the first GLB chunk is not the JSON document")
        check_claimed_size(path, json_length, 1, size - 20, what="bytes of JSON")
        text = handle.read(json_length)
        chunks: list[int] = []
        position = 20 + json_length
        end = min(size, position + total)  # trimesh reads chunks for `total` bytes after the JSON
        while position + 8 <= end:
            handle.seek(position)
            length, kind = struct.unpack("<II", handle.read(8))
            check_claimed_size(path, length, 1, size - position - 8, what="bytes in a GLB chunk")
            if kind == _GLB_BIN:
                chunks.append(length)
            position += 8 + length
    return _check_gltf(path, _parse_json(path, text), chunks)


def _parse_json(path: StrPath, text: bytes) -> Any:
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise FileFormatError(path, f"the glTF JSON cannot be parsed: {type(exc).__name__}: "
                                    f"{str(exc)[:200]}") from None


def _check_stl(path: StrPath) -> None:
    """A binary STL's triangle count must match its size exactly (84 + 50 per triangle);
    otherwise the file must be ASCII text starting with ``solid``."""
    size = os.path.getsize(path)
    with open(path, "rb") as handle:
        head = handle.read(_HEAD_BYTES)
    if size >= 84 and 84 + 50 * struct.unpack_from("<I", head, 80)[0] == size:
        return
    control = sum(1 for byte in head if byte < 32 and byte not in (9, 10, 12, 13))
    if head.lstrip().lower().startswith(b"solid") and control <= len(head) // 100:
        return  # ASCII STL
    if size < 84:
        raise FileFormatError(path, f"not an STL file: {size} bytes, neither ASCII (solid ...) "
                                    "nor a binary STL (84-byte header)")
    count = struct.unpack_from("<I", head, 80)[0]
    raise FileFormatError(path, f"the binary STL header claims {count} triangles "
                                f"({format_size(84 + 50 * count)}), but the file has "
                                f"{format_size(size)} (truncated, or a lying header)")


def _check_off(path: StrPath) -> None:
    """The vertex and face counts of an OFF file against its size."""
    size = os.path.getsize(path)
    with open(path, "rb") as handle:
        head = handle.read(_HEAD_BYTES).decode("utf-8", errors="replace")
    text = re.sub(r"#[^\n]*", "", head)
    found = re.search(r"(COFF|OFF)", text)
    lines = [line.split() for line in text[found.end():].splitlines()] if found else []
    counts = next((words for words in lines if words), None)
    if counts is None:
        raise FileFormatError(path, "not an OFF file: no OFF keyword followed by a vertex/face "
                                    f"count line in the first {format_size(_HEAD_BYTES)}")
    if len(counts) < 2 or not all(re.fullmatch(r"[+-]?\d{1,19}", w) for w in counts[:2]):
        raise FileFormatError(path, f"the OFF count line {' '.join(counts)[:100]!r} does not "
                                    "start with two whole numbers")
    vertices, faces = int(counts[0]), int(counts[1])
    check_claimed_size(path, vertices, 6, size, what="vertices")  # a line "0 0 0\n" each
    check_claimed_size(path, faces, 2, size - 6 * vertices, what="faces")


#: a whole-number token 0 (the candidates for a face's vertex 0; OBJ counts vertices from 1)
_ZERO_TOKEN = re.compile(rb"[ \t][+-]?0+(?=[/ \t\r\n]|$)")


def _check_obj(path: StrPath) -> None:
    """An OBJ's faces count their vertices from 1 (negative: back from the last); index 0 is
    no vertex, and trimesh reads it as another vertex without a word. The zero tokens are found
    first (a plain scan: 1.3 CPU s on 74 MB, trimesh then takes 5.6), then their lines looked at."""
    with open(path, "rb") as handle:
        data = handle.read()
    for found in _ZERO_TOKEN.finditer(data):
        start = data.rfind(b"\n", 0, found.start()) + 1
        if data[start:found.start() + 1].lstrip(b" \t").startswith((b"f ", b"f\t")):
            line = data.count(b"\n", 0, found.start()) + 1
            raise FileFormatError(path, "a face refers to vertex 0, but OBJ counts vertices "
                                        "from 1", line=line)


def _check_before_trimesh(path: StrPath, suffix: str) -> dict[str, bytes] | None:
    """The count checks for ``suffix``; for glTF / GLB, the external buffers to resolve."""
    if suffix == ".stl":
        _check_stl(path)
    elif suffix == ".obj":
        _check_obj(path)
    elif suffix == ".off":
        _check_off(path)
    elif suffix == ".ply":
        from nurbs_core.io import ply

        ply.walk_list_elements(path)
    elif suffix == ".glb":
        return _check_glb(path)
    elif suffix == ".gltf":
        with open(path, "rb") as handle:
            return _check_gltf(path, _parse_json(path, handle.read()), [])
    return None


@contextlib.contextmanager
def _quiet_trimesh() -> Iterator[None]:
    """trimesh logs recoverable parse problems as warnings with a full traceback (printed on
    stderr when the application has no logging set up); a reader reports problems as its own
    FileFormatError instead, so those warnings are held back while a file is read (used as a
    decorator: a fresh context on every call)."""
    logger = logging.getLogger("trimesh")
    previous = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(previous)


def _load_trimesh(path: StrPath, suffix: str) -> TrimeshGeometry:
    import trimesh

    external = _check_before_trimesh(path, suffix)
    kwargs: dict[str, Any] = {"process": False, "skip_materials": True}
    if suffix == ".obj":
        kwargs["maintain_order"] = True  # keep the file's vertex order
    if external is not None:  # only the buffers checked above, never other files
        kwargs["resolver"] = trimesh.resolvers.ZipResolver(external)
    loaded: TrimeshGeometry | None
    try:
        with np.errstate(invalid="ignore", over="ignore"):  # NaN / inf are refused below
            loaded = trimesh.load(str(path), **kwargs)
            if isinstance(loaded, trimesh.Scene):  # GLB/GLTF: every node with its transform
                loaded = loaded.to_mesh() if len(loaded.geometry) else None
    except MemoryError:
        raise FileFormatError(path, "not enough memory to read this mesh") from None
    except Exception as exc:  # trimesh raises many different types for unreadable files
        raise FileFormatError(path, f"not a readable {suffix.lstrip('.').upper()} mesh: "
                                    f"{type(exc).__name__}: {str(exc)[:300]}") from None
    if loaded is None:
        raise FileFormatError(path, "the file contains no geometry")
    return loaded


def _check_faces(path: StrPath, faces: np.ndarray, vertex_count: int) -> None:
    if faces.size and (faces.min() < 0 or faces.max() >= vertex_count):
        bad = int(faces.max() if faces.max() >= vertex_count else faces.min())
        raise FileFormatError(path, f"a face refers to vertex {bad}, but the mesh has "
                                    f"{vertex_count} vertices")


#: an OBJ face line of 5 or more corners (trimesh splits it into a fan of triangles)
_OBJ_POLYGON = re.compile(rb"^[ \t]*f((?:[ \t]+[^ \t\r\n]+){5,})[ \t]*\r?$", re.MULTILINE)
#: a fan triangle turned further than this from its polygon's normal (cosine of 60 degrees)
_FAN_MIN_COSINE = 0.5


def _whole_numbers(words: list[str] | list[bytes]) -> np.ndarray | None:
    """The words as whole numbers (K,) int64, or None when one is not."""
    try:
        return np.array([int(word) for word in words], np.int64)
    except (ValueError, OverflowError):
        return None


def _off_polygons(path: StrPath) -> Iterator[np.ndarray]:
    """The corners of an OFF file's faces of 5 or more corners (its face lines: a corner count
    then the corners' vertex indices; trimesh has read the file, so its counts are good)."""
    with open(path, "rb") as handle:
        text = re.sub(r"#[^\n]*", "", handle.read().decode("utf-8", errors="replace"))
    found = re.search(r"(COFF|OFF)", text)
    if found is None:
        return
    lines = [line.split() for line in text[found.end():].splitlines() if line.strip()]
    if not lines or len(lines[0]) < 2:
        return
    vertex_count, face_count = int(lines[0][0]), int(lines[0][1])
    for words in lines[1 + vertex_count:1 + vertex_count + face_count]:
        if len(words) > 5 and words[0].isdigit() and int(words[0]) >= 5:
            corners = _whole_numbers(words[1:1 + int(words[0])])
            if corners is not None:
                yield corners


def _polygons(path: StrPath, suffix: str, mesh: trimesh.Trimesh) -> Iterator[np.ndarray]:
    """The corner indices of every face of 5 or more corners of an OBJ, OFF or PLY file
    (indices into ``mesh.vertices``; out-of-range ones are refused by the caller)."""
    vertex_count = len(mesh.vertices)
    if suffix == ".obj":
        with open(path, "rb") as handle:
            data = handle.read()
        for found in _OBJ_POLYGON.finditer(data):
            corners = _whole_numbers([token.split(b"/")[0] for token in found.group(1).split()])
            if corners is not None:  # trimesh has read the face; its checks name bad ones
                yield np.where(corners < 0, corners + vertex_count, corners - 1)
    elif suffix == ".off":
        yield from _off_polygons(path)
    elif suffix == ".ply":
        raw = mesh.metadata.get("_ply_raw", {}).get("face", {}).get("data", {})
        lists = raw.get("vertex_indices", raw.get("vertex_index")) if isinstance(raw, dict) else None
        if lists is None or (isinstance(lists, np.ndarray) and lists.dtype != object
                             and (lists.ndim != 2 or lists.shape[1] < 5)):
            return
        for corners in lists:
            if len(corners) >= 5:
                yield np.asarray(corners, np.int64)


def _check_polygons(path: StrPath, suffix: str, mesh: trimesh.Trimesh) -> None:
    """trimesh splits a face of many corners into a fan of triangles from its first corner:
    when the corners are not on one plane (or the polygon turns back on itself), the fan's
    triangles cut through the shape as slivers, and sampling them gives a tangle of points that
    no surface fits (a 162-corner face of a sphere's vertices took 10 minutes). Such a face is
    refused with its size, before any sampling."""
    vertices = np.asarray(mesh.vertices, np.float64)
    for corners in _polygons(path, suffix, mesh):
        if corners.min() < 0 or corners.max() >= len(vertices):
            continue  # refused by _check_faces with the vertex it names
        points = vertices[corners]
        fan = np.cross(points[1:-1] - points[0], points[2:] - points[0])
        normal = fan.sum(axis=0)
        lengths = np.linalg.norm(fan, axis=1)
        scale = float(np.linalg.norm(normal)) * lengths
        kept = scale > 0
        if not kept.any() or not np.all(fan[kept] @ normal >= _FAN_MIN_COSINE * scale[kept]):
            raise FileFormatError(path, f"a face of {len(corners)} corners is not a flat polygon, "
                                        "so its triangles would cut through the shape; save the "
                                        "mesh as triangles, or the scan as points")


def _sample(path: StrPath, mesh: trimesh.Trimesh, count: int, seed: int) -> PointCloud:
    """``count`` points uniform over the area of a trimesh.Trimesh (trimesh's area-weighted
    sampling) with their face normals and face indices."""
    import trimesh

    if count < 1:
        raise ValueError(f"sample_count must be positive, got {count}")
    try:
        area = mesh.area
        if not area > 0:
            raise FileFormatError(path, "the mesh has zero area, so it cannot be sampled")
        points, face_index = trimesh.sample.sample_surface(mesh, int(count), seed=seed)
        normals = np.asarray(mesh.face_normals[face_index], dtype=np.float64)
    except FileFormatError:
        raise
    except Exception as exc:  # degenerate data trimesh cannot sample
        raise FileFormatError(path, f"the mesh cannot be sampled: {type(exc).__name__}: "
                                    f"{str(exc)[:300]}") from None
    attributes = {"normals": normals, "face_index": np.asarray(face_index)}
    return PointCloud(check_points(path, np.asarray(points, dtype=np.float64)), attributes,
                      os.fspath(path))


@_quiet_trimesh()
def sample_mesh_points(path: StrPath, vertices: np.ndarray, faces: np.ndarray, count: int = 100_000,
                       seed: int = 0) -> PointCloud:
    """``count`` points uniform over the area of the triangle mesh (vertices (V, 3), faces
    (F, 3)) read from ``path`` (by :func:`read_mesh_faces`), as ``load_points(path,
    mesh_mode="sample")`` gives them, without reading the file again."""
    import trimesh

    check_points(path, vertices)
    _check_faces(path, faces, len(vertices))
    return _sample(path, trimesh.Trimesh(vertices, faces, process=False), count, seed)


@_quiet_trimesh()
def read_mesh_points(path: StrPath, suffix: str, mesh_mode: str = "vertices",
                     sample_count: int = 100_000, seed: int = 0) -> PointCloud:
    """The vertices of a mesh file (points (V, 3) float64, vertex colors if any), or with
    ``mesh_mode="sample"`` ``sample_count`` points (N, 3) uniform over its area with their
    ``normals`` (N, 3) and ``face_index`` (N,)."""
    import trimesh

    if mesh_mode not in MESH_MODES:
        raise ValueError(f"mesh_mode must be one of {MESH_MODES}, got {mesh_mode!r}")
    mesh = _load_trimesh(path, suffix)
    vertices = np.asarray(getattr(mesh, "vertices", np.empty((0, 3))), dtype=np.float64)
    if vertices.ndim != 2 or len(vertices) == 0:
        raise FileFormatError(path, "the file contains no vertices")
    faces = np.asarray(getattr(mesh, "faces", np.empty((0, 3))))
    attributes: dict[str, np.ndarray] = {}
    if mesh_mode == "sample" and isinstance(mesh, trimesh.Trimesh) and len(faces) > 0:
        check_points(path, vertices)
        _check_faces(path, faces, len(vertices))
        _check_polygons(path, suffix, mesh)
        return _sample(path, mesh, sample_count, seed)
    if suffix == ".stl":  # STL repeats each vertex once per triangle
        vertices, first = np.unique(vertices, axis=0, return_index=True)
        vertices = vertices[np.argsort(first)]
    else:
        colors = getattr(getattr(mesh, "visual", None), "vertex_colors", None)
        if getattr(getattr(mesh, "visual", None), "kind", None) == "vertex" and colors is not None \
                and len(colors) == len(vertices):
            attributes["colors"] = np.asarray(colors)
    check_points(path, vertices)
    return PointCloud(vertices, attributes, os.fspath(path))


@_quiet_trimesh()
def read_mesh_faces(path: StrPath, suffix: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The file's triangle mesh as (vertices (V, 3) float64, faces (F, 3) int64), duplicate
    vertices merged (STL), or None when the file has no faces. Its vertices are checked as a
    cloud's points are (finite, within the fit's range: FileFormatError)."""
    import trimesh

    mesh = _load_trimesh(path, suffix)
    faces = np.asarray(getattr(mesh, "faces", np.empty((0, 3))))
    if not isinstance(mesh, trimesh.Trimesh) or len(faces) == 0:
        return None
    vertices = np.asarray(mesh.vertices, np.float64)
    _check_polygons(path, suffix, mesh)
    # before trimesh's processing, which drops NaN / inf vertices and their triangles without a
    # word (a closed mesh became an open one and took another route)
    check_points(path, vertices)
    _check_faces(path, faces, len(vertices))
    try:
        merged = trimesh.Trimesh(vertices, faces, process=True)
    except Exception as exc:  # degenerate data trimesh cannot process
        raise FileFormatError(path, f"the mesh cannot be processed: {type(exc).__name__}: "
                                    f"{str(exc)[:300]}") from None
    return np.asarray(merged.vertices, np.float64), np.asarray(merged.faces, np.int64)
