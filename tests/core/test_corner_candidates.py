"""The square's corners on a scan's border: the boundary's sharpest turns
(:func:`nurbs_core.surfacing.disk.turn_peaks`)."""

from __future__ import annotations

import numpy as np
import pytest

from nurbs_core.surfacing.disk import turn_peaks
from nurbs_core.surfacing.mesh import cloud_mesh
from nurbs_core.surfacing.parameterize import mesh_parameterization

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_the_four_sharpest_turns_of_a_rectangle_are_its_corners():
    u, v = np.meshgrid(np.linspace(0, 3, 31), np.linspace(0, 1, 11), indexing="ij")
    points = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], -1)
    mesh = cloud_mesh(points)
    param = mesh_parameterization(points, mesh)
    loop = param.topology.loops[0]
    peaks, turning = turn_peaks(param.mesh.vertices, loop, param.mesh.faces, 6)
    corners = {(0.0, 0.0), (3.0, 0.0), (0.0, 1.0), (3.0, 1.0)}
    found = {tuple(np.round(param.mesh.vertices[loop[p], :2], 6)) for p in peaks[:4]}
    assert found == corners
    assert np.degrees(turning[:4]) == pytest.approx(90, abs=1)
    assert (np.degrees(turning[4:]) < 10).all()
