"""Render default fits from both sides: a curled sheet, a terrain (height field) and a closed
shape (a sphere, as a patch network), front faces blue and back faces red, the cloud in black.

A fold shows as a red fleck on a blue side (or the reverse), a curtain as a sheet with no points
on it, an overlap as two layers. Prints each fit's status and quality measures beside the image.

    xvfb-run -a .venv/bin/python benchmarks/render_fits.py [--out /tmp/renders] [--points 4000]
        [--solver gradient] [--iterations 100]

``--solver gradient``: the single patches (and a tube, closed in one direction, one patch cut
open along a seam) go on from the least-squares core with the gradient fit, whose final state
is the one the engine keeps (its best, or the core's fit when that is closer or cleaner; the
printed message says which).

``--learned``: instead, the gradient fit (100 iterations) of held-out clouds of
``bench_learned.py`` (the CAD extrusion face whose learned fit ends farthest above today's, a
generated patch and a leaflet where its core fit wins), a curled sheet and a terrain from
today's default start and from the learned start, side by side per cloud (today's left); a
sphere's learned fit is refused (one patch cannot hold it).
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
    parser.add_argument("--learned", action="store_true", help="plane vs learned starts")
    parser.add_argument("--solver", choices=("auto", "gradient"), default="auto")
    parser.add_argument("--iterations", type=int, default=500)
    args = parser.parse_args(argv)

    import torch

    from nurbs_core import samples
    from nurbs_core.fitting import FitConfig, fit
    from nurbs_core.patches.options import PatchOptions
    from nurbs_core.patches.pipeline import fit_patches

    torch.set_num_threads(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.learned:
        _learned(out)
        return
    shapes = [("curled_sheet", samples.curled_sheet), ("terrain", samples.height_field)]
    if args.solver == "gradient":
        shapes.append(("tube", samples.tube))
    config = FitConfig(solver=args.solver, iterations=args.iterations, threads=1)
    for name, make in shapes:
        shape = make(args.points)
        result = fit(shape.points, config)
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
    print(f"wrote {out}: {', '.join(name for name, _ in shapes)}, sphere (png)")


def _learned(out: Path) -> None:
    import numpy as np
    import pyvista as pv

    from nurbs_core.fitting import FitConfig, fit
    from nurbs_core.quality import surface_quality

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_learned import held_out_clouds

    from nurbs_core import samples

    clouds = held_out_clouds(24, 12)
    chosen = [c for c in clouds
              if c[0] in ("cad #1 extrusion", "test split #7", "leaflet_like seed 103")]
    chosen += [("curled sheet", samples.curled_sheet(700, seed=104).points),
               ("terrain", samples.height_field(700, seed=102).points)]
    base = FitConfig(solver="gradient", iterations=100, threads=1)
    try:  # a closed shape: one patch cannot hold it, learned or not
        fit(samples.sphere(700).points, base.replace(init="learned"))
    except ValueError as exc:
        print(f"sphere from the learned start: refused ({exc})")
    for name, points in chosen:
        results = [fit(points, base), fit(points, base.replace(init="learned"))]
        for label, result in zip(("default", "learned"), results, strict=True):
            q = surface_quality(result.geometry, points)
            print(f"{name} from the {label} start: rms {result.statistics['rms']:.4g}, flipped "
                  f"{q['flipped_fraction']:.3f}, overlap {q['overlap_fraction']:.3f}, coverage "
                  f"{q['coverage']:.3f} ({result.message})")
        slug = name.split(" (")[0].replace(" ", "_").replace("#", "")
        for side, elevation in (("front", 30), ("back", -150)):
            plotter = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(1400, 650))
            for k, result in enumerate(results):
                plotter.subplot(0, k)
                plotter.add_mesh(_grid_mesh(result.geometry, 80), color="#5b8fd9",
                                 backface_params={"color": "#d9675b"}, smooth_shading=True)
                plotter.add_points(np.asarray(points)[::2], color="black", point_size=2)
                plotter.view_isometric()
                plotter.camera.elevation = elevation
                plotter.add_text(f"{name}: {('default', 'learned')[k]} start, 100 iterations",
                                 font_size=9)
            plotter.screenshot(str(out / f"learned_{slug}_{side}.png"))
            plotter.close()
    print(f"wrote {out}/learned_*.png")


if __name__ == "__main__":
    main()
