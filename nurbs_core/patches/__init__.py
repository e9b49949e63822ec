"""Whole objects as networks of B-spline patches: a quad layout of the object's mesh, patches
sharing their boundary control points (exact G0), one joint fit with tangent continuity.

* ``layout``    a quad layout of a triangle mesh (Instant Meshes), cleaned and oriented
* ``network``   the patch network: shared control points, adjacency, valences
* ``fit``       the joint least-squares fit of every patch (fairing, G1, parameter correction)
* ``measures``  gaps, seam angles (regular and irregular corners), orientation, area, distances
"""
