"""Default settings of a patch-network fit (no heavy imports: the app's settings read them).

Stiffness is the fairing weight relative to the data term (by the traces of the two forms;
grids of few control points take a share of it, see ``fit._fairing_share``). 3 against 1e-4
on 10,000-point clouds (``benchmarks/bench_patches.py`` cases, noise 0.2%): the surface's mean
distance to the truth falls from 0.24 to 0.14 noise sigmas (sphere), 0.25 to 0.21 (torus),
0.54 to 0.36 (rounded box), 0.25 to 0.16 (capsule); every seam of those stays within 2
degrees. The seam weight scales the tangent-continuity rows.
"""

STIFFNESS = 3.0
SEAM_WEIGHT = 2.0
