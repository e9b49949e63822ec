"""Default settings of a patch-network fit (no heavy imports: the app's settings read them).

Stiffness is the fairing weight relative to the data term (by the traces of the two forms;
grids of few control points take a share of it, see ``fit._fairing_share``). 3 against 1e-4:
the fitted surface's mean distance to the truth, in noise sigmas, is 0.15 / 0.23 / 0.23 / 0.42
against 0.24 / 0.26 / 0.31 / 0.52 on the sphere, torus, capsule and rounded box of
``python benchmarks/bench_patches.py --cases sphere torus capsule rounded_box --no-single
[--stiffness 1e-4]`` (column ``s2t/sigma``); at 3 every seam there stays within 1.8 degrees.
The seam weight scales the tangent-continuity rows.
"""

STIFFNESS = 3.0
SEAM_WEIGHT = 2.0
#: Seam angle 99th percentile (degrees) above which a network's report warns (and its status is
#: not "converged"); the fit polishes its seams while they are above it and still straighten.
WARN_SEAM = 2.0
#: Largest angle (degrees) of a G1 seam anywhere above which a network's report warns: 15 times
#: the 99th percentile's limit, a visible edge or a fold (a pleat turns its seam by 90 degrees
#: and more) that a small percentile hides.
WARN_SEAM_MAX = 30.0
#: the fewest points a patch network is fitted to (fewer: one patch)
MIN_NETWORK_POINTS = 100
