"""Default settings of a patch-network fit (no heavy imports: the app's settings read them).

Stiffness is the fairing weight relative to the data term (by the traces of the two forms;
grids of few control points take a share of it, see ``fit._fairing_share``). 3 against 1e-4:
the fitted surface's mean distance to the truth, in noise sigmas, is 0.15 / 0.23 / 0.23 / 0.42
against 0.24 / 0.26 / 0.31 / 0.52 on the sphere, torus, capsule and rounded box of
``python benchmarks/bench_patches.py --cases sphere torus capsule rounded_box --no-single
[--stiffness 1e-4]`` (column ``s2t/sigma``); at 3 every seam there stays within 1.8 degrees.
The seam weight scales the tangent-continuity rows.

Over noisy scans the stiffness and the seam weight grow with the noise (:func:`noise_weights`): a bump of the
noise's height over a patch's control spacing tilts the surface in proportion to the noise, so
the same stiffness that leaves a 0.2%-noise scan's detail crumples a 2%-noise scan (its area
11% over the truth's).
"""

STIFFNESS = 3.0
#: Noise estimate, as a share of the cloud's bounding-box diagonal, up to which the stiffness is
#: taken as given; above it, it grows with the noise's square (:func:`noise_weights`).
NOISE_FAIRING_FROM = 0.005
#: ... up to a noise this many times that share (:func:`noise_ratio`).
NOISE_RATIO_MAX = 10.0
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


def noise_ratio(noise_share: float) -> float:
    """How much noisier than :data:`NOISE_FAIRING_FROM` a scan is whose noise estimate is
    ``noise_share`` of its bounding-box diagonal: 1 up to it, at most
    :data:`NOISE_RATIO_MAX`."""
    return min(max(1.0, noise_share / NOISE_FAIRING_FROM), NOISE_RATIO_MAX)


def noise_weights(stiffness: float, seam_weight: float, noise_share: float
                  ) -> tuple[float, float]:
    """The stiffness and seam weight a network fit uses over a scan whose noise estimate is
    ``noise_share`` of its diagonal: as given up to :data:`NOISE_FAIRING_FROM`; above it, with
    r = :func:`noise_ratio`, the stiffness times r^2 and the seam weight times r. The fitted
    surface's wrinkles grow with the noise, so the fairing that keeps them flat grows as the
    data term's residual does, with the noise's square (as a smoothing spline's smoothing
    parameter grows with the noise variance); each patch's fairing then flattens it on its own,
    and the tilt the noise gives the patches at their seams grows with the noise, so the
    tangent rows that hold the seams straight grow with it too."""
    ratio = noise_ratio(noise_share)
    return stiffness * ratio ** 2, seam_weight * ratio
