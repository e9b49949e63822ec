"""The numpy twins of the geometry classes: what .numpy() returns, typed and immutable, read as
attributes or (for older code) as a mapping, rebuilt exactly, importable without torch."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from nurbs_core import NurbsCurve, NurbsSurface, geometry_from_numpy
from nurbs_core.geometry_arrays import CurveArrays, SurfaceArrays, from_mapping


def _surface(dtype=torch.float64) -> NurbsSurface:
    rng = np.random.default_rng(0)
    return NurbsSurface(rng.normal(size=(5, 4, 3)), 3, 2, weights=rng.uniform(0.5, 2, (5, 4)),
                        dtype=dtype)


def test_numpy_returns_a_typed_twin_that_rebuilds_the_same_geometry():
    surface = _surface()
    arrays = surface.numpy()
    assert isinstance(arrays, SurfaceArrays) and arrays.kind == "surface"
    assert (arrays.degree_u, arrays.degree_v, arrays.control_points.shape) == (3, 2, (5, 4, 3))
    rebuilt = geometry_from_numpy(arrays)
    u = torch.rand(50, dtype=torch.float64)
    v = torch.rand(50, dtype=torch.float64)
    torch.testing.assert_close(rebuilt.evaluate(u, v), surface.evaluate(u, v), rtol=0, atol=0)
    curve = NurbsCurve(np.random.default_rng(1).normal(size=(6, 2)), 3)
    twin = curve.numpy()
    assert isinstance(twin, CurveArrays) and twin.knots.shape == (10,)
    np.testing.assert_array_equal(NurbsCurve.from_numpy(twin).control_points.numpy(),
                                  twin.control_points)
    assert _surface(torch.float32).numpy().control_points.dtype == np.float32


def test_the_twin_is_immutable_and_reads_like_the_former_dict():
    arrays = _surface().numpy()
    with pytest.raises(dataclasses.FrozenInstanceError):
        arrays.degree_u = 2
    with pytest.raises(TypeError):
        arrays["degree_u"] = 2  # a read-only mapping
    assert arrays["kind"] == "surface" and arrays.get("knots_u") is arrays.knots_u
    assert list(arrays) == ["kind", "degree_u", "degree_v", "control_points", "weights",
                            "knots_u", "knots_v"]
    moved = arrays.replace(control_points=arrays.control_points + 1.0)
    np.testing.assert_array_equal(moved.control_points, arrays.control_points + 1.0)
    assert moved.knots_u is arrays.knots_u


def test_json_form_round_trips_and_bad_entries_are_refused():
    arrays = _surface().numpy()
    back = from_mapping(json.loads(json.dumps(arrays.to_json())))
    for key in arrays:
        np.testing.assert_array_equal(np.asarray(back[key]), np.asarray(arrays[key]))
    assert from_mapping(arrays) is arrays
    with pytest.raises(ValueError, match="unknown geometry kind 'mesh'"):
        from_mapping({"kind": "mesh"})
    with pytest.raises(ValueError, match="a curve needs 'knots'"):
        from_mapping({"kind": "curve", "degree": 2, "control_points": [[0, 0], [1, 1], [2, 0]]})


@pytest.mark.parametrize("change, message", [
    ({"degree_u": "3"}, "degree_u must be an integer, got '3'"),
    ({"degree_v": 3.0}, "degree_v must be an integer, got 3.0"),
    ({"degree_u": True}, "degree_u must be an integer, got True"),
    ({"knots_v": ["0"] * 4 + ["1"] * 4}, "knots_v must hold numbers"),
    ({"weights": [[True] * 4] * 4}, "weights must hold numbers"),
    ({"control_points": [[[0, 0, 0]] * 4] * 3 + [[[0, 0]]]}, "control_points must be a"),
])
def test_values_of_the_wrong_type_are_never_coerced(change, message):
    """int("3") is 3 and np.asarray(["1"], float) is [1.0]: the session form refuses both."""
    knots = [0.0] * 4 + [1.0] * 4
    good = {"kind": "surface", "degree_u": 3, "degree_v": 3,
            "control_points": np.zeros((4, 4, 3)).tolist(), "weights": np.ones((4, 4)).tolist(),
            "knots_u": knots, "knots_v": knots}
    assert from_mapping(good).degree_u == 3
    with pytest.raises(ValueError, match=message):
        from_mapping({**good, **change})


def test_the_twins_import_without_torch():
    code = "import sys, nurbs_core.geometry_arrays; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
