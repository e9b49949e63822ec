"""Render default fits from both sides: a curled sheet, a terrain (height field) and a closed
shape (a sphere, as a patch network), front faces blue and back faces red, the cloud in black.

A fold shows as a red fleck on a blue side (or the reverse), a curtain as a sheet with no points
on it, an overlap as two layers. Prints each fit's status and quality measures beside the image.

    xvfb-run -a .venv/bin/python benchmarks/render_fits.py [--out /tmp/renders] [--points 4000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

MEASURES = ("rms", "flipped_fraction", "overlap_fraction", "coverage", "area_ratio")


def _grid_mesh(surface, samples: int):
    import pyvista as pv
    import torch

    t = torch.linspace(0, 1, samples, dtype=torch.float64)
    grid = surface.evaluate_grid(t, t).detach().numpy()
    return pv.StructuredGrid(grid[..., 0], grid[..., 1], grid[..., 2]).extract_surface(
        algorithm="dataset_surface")


def _render(meshes, points, path: Path, views) -> None:
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, shape=(1, len(views)),
                         window_size=(700 * len(views), 650))
    for k, (elevation, azimuth) in enumerate(views):
        plotter.subplot(0, k)
        for mesh in meshes:
            plotter.add_mesh(mesh, color="#5b8fd9", backface_params={"color": "#d9675b"},
                             smooth_shading=True)
        plotter.add_points(points[::4], color="black", point_size=2)
        plotter.view_isometric()
        plotter.camera.elevation, plotter.camera.azimuth = elevation, azimuth
        plotter.add_text(f"elevation {elevation}, azimuth {azimuth} (blue front, red back)",
                         font_size=9)
    plotter.screenshot(str(path))
    plotter.close()


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="renders")
    parser.add_argument("--points", type=int, default=4000)
    args = parser.parse_args(argv)

    import torch

    from nurbs_core import samples
    from nurbs_core.fitting import FitConfig, fit
    from nurbs_core.patches.options import PatchOptions
    from nurbs_core.patches.pipeline import fit_patches

    torch.set_num_threads(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, make in (("curled_sheet", samples.curled_sheet), ("terrain", samples.height_field)):
        shape = make(args.points)
        result = fit(shape.points, FitConfig())
        measures = {k: round(float(result.statistics[k]), 4) for k in MEASURES
                    if k in result.statistics}
        print(f"{name}: {result.status} {measures} ({result.message})")
        _render([_grid_mesh(result.geometry, 80)], shape.points, out / f"{name}.png",
                [(20, 0), (-160, 0)])
    shape = samples.sphere(args.points)
    network = fit_patches(shape.points, PatchOptions())
    quality = network.quality
    print(f"sphere: {quality.patches} patches, flipped {quality.flipped_fraction:.4f}, "
          f"c2s rms {quality.c2s_rms:.4g}, area {quality.area:.4f} (4 pi = 12.566)")
    _render([_grid_mesh(s, 20) for s in network.network.surfaces()], shape.points,
            out / "sphere.png", [(20, 0), (20, 180)])
    print(f"wrote {out}/curled_sheet.png, terrain.png, sphere.png")


if __name__ == "__main__":
    main()
