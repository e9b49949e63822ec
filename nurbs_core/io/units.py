"""Length units of a model, as the formats that carry them write them.

A scan's coordinates are numbers; the unit says what they measure. The CAD formats carry it
(.3dm's model unit system, STEP's and IGES's length unit); without one a CAD tool assumes its
own, so a scan in metres arrived in Rhino 1000 x too small. ``units`` is one of :data:`UNITS`,
or None when unknown: .3dm then says so ("None": no unit, no scaling on import), STEP and IGES
(which must name one) say millimetres. The coordinates are never scaled.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any

#: The length units a model may declare (the CLI's ``--units``).
UNITS = ("mm", "cm", "m", "in", "ft")
_OCC = {"mm": "MM", "cm": "CM", "m": "M", "in": "INCH", "ft": "FT"}
_RHINO = {"mm": "Millimeters", "cm": "Centimeters", "m": "Meters", "in": "Inches",
          "ft": "Feet"}
#: The unit STEP and IGES are written in when none is known.
DEFAULT_CAD_UNITS = "mm"


def check_units(units: str | None) -> str | None:
    """``units`` itself when it is one of :data:`UNITS` or None; ValueError otherwise."""
    if units is not None and units not in UNITS:
        raise ValueError(f"unknown units {units!r}: one of {', '.join(UNITS)}")
    return units


def occ_unit(units: str | None) -> str:
    """OpenCASCADE's name of the unit (``write.step.unit``, ``xstep.cascade.unit``)."""
    return _OCC[check_units(units) or DEFAULT_CAD_UNITS]


def rhino_unit_system(units: str | None) -> Any:
    """``rhino3dm.UnitSystem`` of the unit (``None`` when unknown)."""
    import rhino3dm

    checked = check_units(units)
    return getattr(rhino3dm.UnitSystem, "None" if checked is None else _RHINO[checked])


#: The library names of a unit a file states -> ours: openNURBS's UnitSystem names (.3dm)
#: and OpenCASCADE's (STEP). Others (microns, kilometres, yards...) are units we do not offer.
_FROM_LIBRARY = {**{name: unit for unit, name in _RHINO.items()},
                 **{name: unit for unit, name in _OCC.items()}}


def units_from_library(name: object) -> str | None:
    """Our unit for openNURBS's ("Meters") or OpenCASCADE's ("M") name of it; None for no
    unit ("None", None) and for units not in :data:`UNITS`."""
    return _FROM_LIBRARY.get(str(name)) if name is not None else None


def units_of_items(items: Iterable[Any]) -> str | None:
    """The length unit NURBS items read from one file state (their ``metadata["units"]``: .3dm,
    STEP and our JSON carry it); None when none states one or they disagree."""
    found = set()
    for item in items:
        metadata = getattr(item, "metadata", None)
        unit = metadata.get("units") if isinstance(metadata, dict) else None
        if unit is not None:
            found.add(unit if isinstance(unit, str) else repr(unit))  # JSON may hold anything
    unit = found.pop() if len(found) == 1 else None
    return unit if unit in UNITS else None


def units_metadata(metadata: dict | None, units: str | None) -> dict | None:
    """JSON metadata with the ``units`` entry (the metadata as it was when ``units`` is None)."""
    return metadata if units is None else {**(metadata or {}), "units": units}


def units_of_file(path: object) -> str | None:
    """The length unit a point-cloud file states: E57 coordinates are metres (ASTM E2807); a
    LAS / LAZ file's coordinate system names its linear unit (:func:`las_units`); the other
    cloud formats carry none (None)."""
    name = str(path).lower()
    if name.endswith(".e57"):
        return "m"
    if name.endswith((".las", ".laz")):
        return las_units(path)
    return None


#: EPSG codes of linear units (GeoTIFF's ProjLinearUnitsGeoKey, VerticalUnitsGeoKey) -> ours;
#: the US survey foot (9003) is not the foot (2 ppm apart) and is left unknown
_EPSG_UNITS = {9001: "m", 9002: "ft"}
#: GeoTIFF keys naming a linear unit: projected, vertical
_GEO_LINEAR_KEYS = (3076, 4099)
_WKT_UNIT = re.compile(r'(?:UNIT|LENGTHUNIT)\s*\[\s*"([^"]+)"')
_WKT_UNITS = {"metre": "m", "meter": "m", "metres": "m", "meters": "m", "foot": "ft",
              "international foot": "ft", "feet": "ft", "millimetre": "mm", "millimeter": "mm",
              "centimetre": "cm", "centimeter": "cm", "inch": "in"}
_ANGULAR = ("degree", "radian", "grad", "arc-second", "arc-minute")


def las_units(path: object) -> str | None:
    """The linear unit a LAS / LAZ file's coordinate system states: its GeoTIFF keys
    (projected and vertical linear units, EPSG codes) or its OGC WKT (the length units named),
    when every unit named is one of :data:`UNITS` and they agree; else None (also when laspy is
    missing or the header does not read). Only the header and its records are read."""
    try:
        import laspy

        from nurbs_core.io.scans import check_las_header

        check_las_header(str(path))
        with laspy.open(str(path)) as reader:
            records = list(reader.header.vlrs) + list(getattr(reader, "evlrs", None) or [])
    except Exception:  # noqa: BLE001 - no unit known; reading the points says what is wrong
        return None
    found: set[str | None] = set()
    for record in records:
        for key in getattr(record, "geo_keys", None) or []:
            if key.id in _GEO_LINEAR_KEYS and key.tiff_tag_location == 0:
                found.add(_EPSG_UNITS.get(int(key.value_offset)))
        text = getattr(record, "string", None)
        if isinstance(text, str):
            for unit in _WKT_UNIT.findall(text):
                unit = unit.strip().lower()
                if not unit.startswith(_ANGULAR):
                    found.add(_WKT_UNITS.get(unit))
    unit = found.pop() if len(found) == 1 else None
    return unit if unit in UNITS else None
