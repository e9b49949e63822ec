"""The deviation report: one HTML file (pictures inline) or a PDF, written with matplotlib.

A report shows what a customer or a colleague needs to judge a fit without our software: the
status and its warnings, the scan's signed distances to the fit from four sides (front, top,
right, iso) in a colour scale centred on zero with the tolerance marked, their histogram with
the tolerance bands (within, above, below), the statistics, the result (route, patches, seams,
folds) and every setting the fit ran with, all in the scan's units.
"""

from __future__ import annotations

import base64
import datetime
import html
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nurbs_core.deviation_bands import BAND_COLOURS, Deviation, histogram
from nurbs_core.up_axis import to_frame

#: Points and triangles drawn in each view at most (a random sample; the statistics use all).
VIEW_POINTS = 12_000
VIEW_TRIANGLES = 6_000
#: (name, elevation, azimuth) of each view, degrees (matplotlib's 3-D axes: z up), in the up
#: axis's frame (:mod:`nurbs_core.up_axis`); :func:`view_titles` names them in world axes.
VIEWS = (("front", 0.0, -90.0), ("top", 90.0, -90.0), ("right", 0.0, 0.0), ("iso", 28.0, -55.0))
SUFFIXES = (".html", ".htm", ".pdf")


@dataclass
class ReportContent:
    """What a report says. ``points`` (N, 3) the scan; ``vertices`` (V, 3) and ``faces`` (F, 3)
    the fit as triangles; ``deviation`` the points' signed distances to them; ``summary`` and
    ``settings`` (label, value) rows; ``units`` the length unit (None: not given); ``program``
    the front end that made it ("nurbs-fit", "nurbs-studio"); ``up_axis`` the axis up in the
    four views ("z", CAD's, or "y", as in the app's View > Up Axis)."""

    title: str
    status: str
    points: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    deviation: Deviation
    units: str | None = None
    #: the fit encloses a volume (outward normals): each view shows the points that face it
    closed: bool = False
    summary: list[tuple[str, str]] = field(default_factory=list)
    settings: list[tuple[str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    program: str = "nurbs-fit"
    #: the world axis up in the views ("z" or "y"; :mod:`nurbs_core.up_axis`)
    up_axis: str = "z"


def write_report(path: str | Path, content: ReportContent) -> None:
    """Write the report as HTML (``.html`` / ``.htm``) or PDF (``.pdf``), atomically."""
    from nurbs_core.atomic import atomic_write

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(f"a report is .html or .pdf, not {path.name!r}")
    figures = [_views_figure(content), _histogram_figure(content)]
    if suffix == ".pdf":
        with atomic_write(path, "wb", encoding=None) as handle:
            _write_pdf(handle, content, figures)
    else:
        text = _html(content, [_png(figure) for figure in figures])
        with atomic_write(path, "w") as handle:
            handle.write(text)


def statistics_rows(content: ReportContent) -> list[tuple[str, str]]:
    """The deviation statistics as (label, value) rows, lengths with their unit."""
    s = content.deviation.statistics()
    unit = f" {content.units}" if content.units else ""

    def length(value: float) -> str:
        return f"{value:.4g}{unit}"

    return [("points", f"{int(s['points']):,}"),
            ("tolerance (+/-)", length(s["tolerance"])),
            ("within the tolerance", f"{s['within']:.2%}"),
            ("above (outside)", f"{s['above']:.2%}"), ("below (inside)", f"{s['below']:.2%}"),
            ("mean distance", length(s["mean"])), ("mean signed distance", length(s["mean_signed"])),
            ("RMS", length(s["rms"])), ("95th percentile", length(s["p95"])),
            ("99th percentile", length(s["p99"])), ("largest above", length(s["max_above"])),
            ("largest below", length(s["max_below"]))]


def _figure(width: float, height: float) -> Any:
    from matplotlib.figure import Figure  # drawn by Agg, without pyplot: no display, no state

    return Figure(figsize=(width, height), dpi=110)


def view_titles(up_axis: str = "z") -> list[str]:
    """The four views' titles with ``up_axis`` up, naming the world axis each looks from:
    "front (from -y)", "top (from +z)", "right (from +x)", "iso" with z up; "front (from +z)",
    "top (from +y)" with y up."""
    to_world = to_frame(up_axis).T
    titles = []
    for name, elevation, azimuth in VIEWS:
        if name == "iso":
            titles.append(name)
            continue
        towards = to_world @ _towards(elevation, azimuth)
        axis = int(np.argmax(np.abs(towards)))
        titles.append(f"{name} (from {'+' if towards[axis] > 0 else '-'}{'xyz'[axis]})")
    return titles


def _towards(elevation: float, azimuth: float) -> np.ndarray:
    """matplotlib's camera direction (3,) for ``elevation`` and ``azimuth`` (degrees)."""
    e, a = np.radians(elevation), np.radians(azimuth)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def _views_figure(content: ReportContent) -> Any:
    """The four views: the fit in light grey, the points coloured by signed distance; drawn in
    the up axis's frame (the coordinates turned so that the chosen axis is matplotlib's z)."""
    from matplotlib import colors
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    rng = np.random.default_rng(0)
    rotation = to_frame(content.up_axis)
    turned = content.points @ rotation.T
    points, d = turned, content.deviation.distances
    normals = content.deviation.normals if content.closed else None
    if normals is not None:
        normals = normals @ rotation.T
    if len(points) > 4 * VIEW_POINTS:
        keep = rng.choice(len(points), 4 * VIEW_POINTS, replace=False)
        points, d = points[keep], d[keep]
        normals = None if normals is None else normals[keep]
    faces = content.faces
    if len(faces) > VIEW_TRIANGLES:
        faces = faces[rng.choice(len(faces), VIEW_TRIANGLES, replace=False)]
    triangles = (content.vertices @ rotation.T)[faces]
    reach = 2.0 * max(content.deviation.tolerance, 1e-300)
    norm = colors.TwoSlopeNorm(vcenter=0.0, vmin=-reach, vmax=reach)
    figure = _figure(11.0, 9.0)
    low, high = turned.min(axis=0), turned.max(axis=0)
    centre, half = 0.5 * (low + high), 0.5 * float((high - low).max()) or 1.0
    scatter = None
    for index, ((_, elevation, azimuth), name) in enumerate(
            zip(VIEWS, view_titles(content.up_axis), strict=True)):
        axes = figure.add_subplot(2, 2, index + 1, projection="3d")
        axes.add_collection3d(Poly3DCollection(triangles, facecolor="#b9c0cc", edgecolor="none",
                                               alpha=0.5))
        shown = _facing(points, normals, elevation, azimuth, rng)
        scatter = axes.scatter(points[shown, 0], points[shown, 1], points[shown, 2],
                               c=np.clip(d[shown], -reach, reach), cmap="coolwarm", norm=norm,
                               s=float(np.clip(30_000 / max(len(shown), 1), 1.5, 8.0)),
                               depthshade=False, linewidths=0)
        axes.view_init(elev=elevation, azim=azimuth)
        for setter, middle in zip((axes.set_xlim, axes.set_ylim, axes.set_zlim), centre,
                                  strict=True):
            setter(middle - half, middle + half)
        axes.set_box_aspect((1, 1, 1))
        axes.set_title(name)
        axes.set_axis_off()
    if scatter is not None:
        bar = figure.colorbar(scatter, ax=figure.axes, shrink=0.6, extend="both")
        unit = f" ({content.units})" if content.units else ""
        bar.set_label(f"signed distance{unit}; tolerance +/-{content.deviation.tolerance:.3g}")
        for level in (-content.deviation.tolerance, content.deviation.tolerance):
            bar.ax.axhline(level, color="black", linewidth=1.0)
    return figure


def _facing(points: np.ndarray, normals: np.ndarray | None, elevation: float, azimuth: float,
            rng: np.random.Generator) -> np.ndarray:
    """Indices of at most VIEW_POINTS points to draw in a view: those whose fit normal faces
    the viewer (all when the normals are not known: an open sheet has no back)."""
    index = np.arange(len(points))
    if normals is not None:
        index = index[normals @ _towards(elevation, azimuth) > 0.0]
    if len(index) > VIEW_POINTS:
        index = np.sort(rng.choice(index, VIEW_POINTS, replace=False))
    return index


def _histogram_figure(content: ReportContent) -> Any:
    """The histogram of the signed distances, its bars coloured by band."""
    deviation = content.deviation
    d = deviation.distances
    tolerance = deviation.tolerance
    figure = _figure(9.0, 3.8)
    axes = figure.add_subplot(1, 1, 1)
    counts, edges, bands = histogram(d, tolerance)
    middles = 0.5 * (edges[:-1] + edges[1:])
    colours = [BAND_COLOURS[band] for band in bands]
    axes.bar(middles, counts, width=np.diff(edges), color=colours, edgecolor="white",
             linewidth=0.4)
    for level in (-tolerance, tolerance):
        axes.axvline(level, color="black", linestyle="--", linewidth=1.0)
    unit = f" ({content.units})" if content.units else ""
    axes.set_xlabel(f"signed distance{unit} (the outer bars hold everything beyond)")
    axes.set_ylabel("points")
    axes.set_title(f"{deviation.within.mean():.1%} within +/-{tolerance:.3g}, "
                   f"{deviation.above.mean():.1%} above, {deviation.below.mean():.1%} below")
    figure.tight_layout()
    return figure


def _png(figure: Any) -> str:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _rows(rows: list[tuple[str, str]]) -> str:
    return "\n".join(f"<tr><th>{html.escape(label)}</th><td>{html.escape(value)}</td></tr>"
                     for label, value in rows)


def _html(content: ReportContent, pictures: list[str]) -> str:
    escape = html.escape
    good = content.status == "converged"
    colour = "#2e7d32" if good else "#b26a00"
    warnings = "".join(f"<li>{escape(w)}</li>" for w in content.warnings)
    when = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    units = content.units or "not given"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>{escape(content.title)}: deviation report</title>
<style>
body {{ font-family: sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }}
table {{ border-collapse: collapse; margin: 0.5em 0 1.5em; }}
th, td {{ border: 1px solid #ccc; padding: 0.25em 0.7em; text-align: left; }}
th {{ background: #f2f4f7; font-weight: normal; }}
.status {{ font-size: 1.3em; font-weight: bold; color: {colour}; }}
img {{ max-width: 100%; }}
.columns {{ display: flex; gap: 2em; flex-wrap: wrap; }}
</style></head><body>
<h1>Deviation report: {escape(content.title)}</h1>
<p class="status">{escape(content.status)}</p>
<p>Made {escape(when)} by NURBS Studio ({escape(content.program)}). Units: {escape(units)}. Distances are
signed along the fitted surface's normal (positive outside a closed result).</p>
{f"<h2>Warnings</h2><ul>{warnings}</ul>" if warnings else ""}
<div class="columns">
<div><h2>Deviation</h2><table>{_rows(statistics_rows(content))}</table></div>
<div><h2>Result</h2><table>{_rows(content.summary)}</table></div>
</div>
<h2>Views</h2>
<img alt="the scan coloured by signed distance: {escape(', '.join(view_titles(content.up_axis)))}"
 src="data:image/png;base64,{pictures[0]}">
<h2>Histogram</h2>
<img alt="histogram of the signed distances" src="data:image/png;base64,{pictures[1]}">
<h2>Settings</h2>
<table>{_rows(content.settings)}</table>
</body></html>
"""


def _write_pdf(handle: Any, content: ReportContent, figures: list[Any]) -> None:
    """Page 1 the text (status, warnings, statistics, result, settings), then the figures."""
    from matplotlib.backends.backend_pdf import PdfPages

    page = _figure(8.27, 11.69)
    lines = [f"Deviation report: {content.title}", f"status: {content.status}",
             f"units: {content.units or 'not given'}", ""]
    lines += [f"warning: {w}" for w in content.warnings]
    for heading, rows in (("Deviation", statistics_rows(content)), ("Result", content.summary),
                          ("Settings", content.settings)):
        lines += ["", heading] + [f"  {label}: {value}" for label, value in rows]
    page.text(0.06, 0.96, "\n".join(lines), va="top", ha="left", family="monospace",
              fontsize=7.5, wrap=True)
    with PdfPages(handle) as pdf:
        pdf.savefig(page)
        for figure in figures:
            pdf.savefig(figure)
