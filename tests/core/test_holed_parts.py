"""Parts with small holes and short walls (``sample_parts.HOLED_PARTS``): the segmentation's
choice between a sphere and a cylinder on a short belt, its search for small holes after the
large faces, and the solids of the flange and the boss plate."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("OCP")

from nurbs_core.brep.occ import face_kind, faces  # noqa: E402
from nurbs_core.brep.part import fit_part  # noqa: E402
from nurbs_core.brep.sample_parts import HOLED_PARTS, scan_part  # noqa: E402
from nurbs_core.brep.segment import segment  # noqa: E402
from nurbs_core.route import choose_route  # noqa: E402

NOISE = 0.002


def _band(latitude: float, count: int, sigma: float, seed: int) -> np.ndarray:
    """Points (count, 3) of a band of the unit sphere (``latitude`` > 0, radians: the band
    reaches that far from the equator) or, with ``latitude`` = 0, of the cylinder of radius 1
    from z = -0.1 to 0.1; uniform by area, Gaussian noise ``sigma``."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, 2 * np.pi, count)
    if latitude > 0:
        z = rng.uniform(-np.sin(latitude), np.sin(latitude), count)
        ring = np.sqrt(1 - z * z)
    else:
        z, ring = rng.uniform(-0.1, 0.1, count), np.ones(count)
    points = np.c_[ring * np.cos(angle), ring * np.sin(angle), z]
    return points + rng.normal(scale=sigma, size=points.shape)


def test_a_short_belt_is_a_cylinder_and_a_wide_sphere_band_stays_a_sphere():
    """A cylinder 0.2 high of radius 1 lies within a noise sigma of the sphere of radius 1
    (the flange's rim), and counting inliers preferred the simpler sphere; the distances tell
    the cylinder by the sag a sphere adds along the axis. A band of the sphere 90 degrees wide
    lies on no cylinder."""
    sigma = 0.006
    belt = segment(_band(0.0, 3000, sigma, 1), noise=sigma)
    assert [s.kind for s in belt.surfaces] == ["cylinder"]
    assert abs(belt.surfaces[0].radius - 1.0) < 0.01
    assert abs(abs(belt.surfaces[0].axis[2]) - 1.0) < 1e-3
    sphere = segment(_band(np.radians(45.0), 3000, sigma, 2), noise=sigma)
    assert [s.kind for s in sphere.surfaces] == ["sphere"]


def _found_kinds(segmentation, owner: np.ndarray, kinds: list[str]) -> np.ndarray:
    """Per true face: the share of its points labelled with a surface of its own type."""
    found = np.array([segmentation.surfaces[k].kind if k >= 0 else "none"
                      for k in segmentation.labels])
    true = np.array(kinds)[owner]
    return np.array([(found[owner == f] == true[owner == f]).mean() for f in range(len(kinds))])


@pytest.mark.slow  # a segmentation of 20,000 points: 6 s, 20 s on the busy machine
def test_the_flange_segments_into_its_rim_and_all_six_bolt_holes():
    """The flange as ``bench_parts.py --random 0 --no-open --no-freeform`` scans it (seed 8):
    the rim was a sphere, and a round won by a 19-point cylinder among 4,835 free points
    (3,800 of them the found faces' blurred edge points) ended the search with 1 of 6 bolt
    holes. Drawn again among the points no surface holds, the rounds find all six."""
    points, owner, kinds = scan_part(HOLED_PARTS["flange"](), 20_000, NOISE, seed=8)
    segmentation = segment(points)
    assert sorted(s.kind for s in segmentation.surfaces) == sorted(kinds)  # 9 cylinders, 3 planes
    holes = [s for s in segmentation.surfaces if s.kind == "cylinder" and s.radius < 0.15]
    assert len(holes) == 6
    assert all(abs(hole.radius - 0.09) < 0.005 for hole in holes)
    assert _found_kinds(segmentation, owner, kinds).min() >= 0.8


@pytest.mark.slow  # a segmentation of 20,000 points: 5 s, 18 s on the busy machine
def test_the_boss_plates_holes_are_cylinders():
    """The boss plate as the default ``bench_parts.py`` scans it (seed 31): the segmentation
    found neither its through hole nor its counterbore (radius 0.15 and 0.27, 0.15 and 0.1
    high; 9 of 11 surfaces) and the solid came out with 3 faces. Retried rounds, seeded where
    no surface holds the points and with cylinders along the axes found (a hole is square to
    its face), find both."""
    points, owner, kinds = scan_part(HOLED_PARTS["boss_plate"](), 20_000, NOISE, seed=31)
    segmentation = segment(points)
    assert sorted(s.kind for s in segmentation.surfaces) == sorted(kinds)  # 3 cylinders, 8 planes
    radii = sorted(s.radius for s in segmentation.surfaces if s.kind == "cylinder")
    assert np.allclose(radii, [0.15, 0.27, 0.3], atol=0.01)


@pytest.mark.slow  # a segmentation and a solid of 20,000 points: 12-13 s, 28 s busy
@pytest.mark.parametrize("name, seed", [("flange", 30), ("boss_plate", 9)])
def test_a_holed_part_is_its_converged_solid_with_exact_faces(name, seed):
    """The flange and the boss plate as the default and the restricted benchmark scan them:
    one valid closed solid, ``converged``, the points on faces of their true type."""
    shape = HOLED_PARTS[name]()
    points, owner, kinds = scan_part(shape, 20_000, NOISE, seed=seed)
    route = choose_route(points)
    assert route.kind == "part" and route.mesh is not None
    result = fit_part(points, route.mesh.vertices, route.mesh.faces, route.segmentation)
    assert result.valid and result.closed and result.status == "converged"
    out_kinds = np.array([face_kind(f) for f in faces(result.solid)])
    assert (out_kinds[result.point_faces] == np.array(kinds)[owner]).mean() >= 0.9
    assert sorted(out_kinds) == sorted(kinds)


@pytest.mark.parametrize("seed", [3, 0])
def test_a_counterbores_short_wall_is_the_cylinder_coaxial_with_its_hole(seed):
    """The boss plate's counterbore (radius 0.27, 0.1 high: about 410 of 20,000 points, every
    normal on it blurred by its floor and rim) came out a sphere of radius 0.278 (seed 3) or
    unlabelled beside a stray cylinder (seed 0): 4 of the 8 default scans (seeds 0-7) lost it.
    Found by distance alone around the through hole's axis, it is the cylinder of radius 0.27
    on all 8."""
    points, owner, kinds = scan_part(HOLED_PARTS["boss_plate"](), 20_000, NOISE, seed=seed)
    segmentation = segment(points)
    assert sorted(s.kind for s in segmentation.surfaces) == sorted(kinds)  # 3 cylinders, 8 planes
    radii = sorted(s.radius for s in segmentation.surfaces if s.kind == "cylinder")
    assert np.allclose(radii, [0.15, 0.27, 0.3], atol=0.005)
    wall = next(k for k, s in enumerate(segmentation.surfaces)
                if s.kind == "cylinder" and abs(s.radius - 0.27) < 0.005)
    # the true face whose points lie 0.27 from the hole's axis (x, y) = (1.45, 0.7)
    counterbore = next(f for f, kind in enumerate(kinds) if kind == "cylinder" and abs(
        np.median(np.linalg.norm(points[owner == f, :2] - [1.45, 0.7], axis=1)) - 0.27) < 0.01)
    assert (segmentation.labels[owner == counterbore] == wall).mean() >= 0.8
