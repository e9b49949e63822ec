"""Counts in OpenCASCADE's B-rep text checked before OpenCASCADE reads it.

``BRepTools::Read`` trusts the counts the text declares: a section header (``Curves 15``)
whose count is larger than the text makes it loop to that count (``Curves 2000000000`` spins for
hours on a 100 KB text), and a triangulation whose header claims 400,000,000 nodes makes it
allocate them (gigabytes) before it finds the data missing. This module checks every section's
count against the lines that follow it (each entity takes at least one line) and walks the
triangulations (their headers give the exact number of values that follow), so a damaged or
hostile text is refused in milliseconds with a ValueError saying which count lies. Other
geometry (B-spline poles) is left to OpenCASCADE. Pure Python.
"""

from __future__ import annotations

import re

#: the sections of the B-rep text format, each a header line ``<name> <count>``
SECTIONS = ("Locations", "Curve2ds", "Curves", "Polygon3D", "PolygonOnTriangulations",
            "Surfaces", "Triangulations", "TShapes")
_HEADER = re.compile(r"^(" + "|".join(SECTIONS) + r")[ \t]+(\S+)[ \t]*$", re.MULTILINE)


def check_brep_text(text: str) -> None:
    """ValueError when a count in the B-rep ``text`` claims more than the text holds: a
    section's entity count beyond the lines after its header, or a triangulation's node or
    triangle count beyond the values left in the text."""
    total_lines = text.count("\n") + 1
    for found in _HEADER.finditer(text):
        name, count = found.group(1), found.group(2)
        if not count.isdigit():
            raise ValueError(f"the B-rep's {name} count {count[:40]!r} is not a whole number")
        left = total_lines - (text.count("\n", 0, found.end()) + 1)
        if int(count) > left:
            raise ValueError(f"the B-rep declares {count} {name}, but only {left} lines "
                             "follow (truncated or damaged)")
        if name == "Triangulations":
            _check_triangulations(text[found.end():], int(count), _version(text))


def _version(text: str) -> int:
    """The format version (``CASCADE Topology V3``: 3); 1 when none is stated."""
    stated = re.search(r"CASCADE Topology V(\d+)", text[:4096])
    return int(stated.group(1)) if stated else 1


def _check_triangulations(rest: str, count: int, version: int) -> None:
    """Walk ``count`` triangulations: a header (nodes, triangles, has UV, [V3+: has normals,]
    deflection) and then 3 values per node, 2 per node with UV, 3 per triangle and 3 per node
    with normals. A count beyond the values left is refused; a text that does not follow this
    layout is left to OpenCASCADE's reader (it fails on it, without allocating by a count)."""
    tokens = rest.split()
    header = 5 if version >= 3 else 4
    at = 0
    for number in range(count):
        if at + header > len(tokens):
            return
        head = tokens[at:at + header]
        if not all(word.isdigit() for word in head[:header - 1]):
            return  # not the layout this walk knows: OpenCASCADE decides
        nodes, triangles, has_uv = int(head[0]), int(head[1]), head[2] == "1"
        has_normals = version >= 3 and head[3] == "1"
        left = len(tokens) - at - header
        values = 3 * nodes + 2 * nodes * has_uv + 3 * triangles + 3 * nodes * has_normals
        if values > left:
            raise ValueError(f"the B-rep's triangulation {number + 1} declares {nodes} nodes and "
                             f"{triangles} triangles ({values} values), but only {left} "
                             "values follow (truncated or damaged)")
        at += header + values
