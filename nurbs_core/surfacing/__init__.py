"""Surfacing a point cloud: its triangle mesh, topology, a fold-free parameterisation and the
fairing least-squares core (numpy + scipy; the fit loop in :mod:`nurbs_core.fitting` drives it).

* ``neighbours``     k-nearest-neighbour frames, spacing and noise estimate
* ``mesh``           a triangle mesh of a cloud (local Delaunay umbrellas, voted and cleaned)
* ``disk``           boundary loops, topology (disk, tube, closed), hole filling, corners
* ``parameterize``   Floater's mean-value map onto the unit square, flip check, point (u, v)
* ``map_crowding``   how much that map crowds part of the surface (one patch or a network)
* ``fairing``        exact thin-plate and membrane energies of a B-spline surface
* ``core``           least squares + fairing + parameter correction, pass by pass
"""
