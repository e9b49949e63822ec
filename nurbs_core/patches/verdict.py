"""What a user is warned of about a fitted network: the quality checks behind its status.

Any warning makes the status "fitted with warnings" instead of "converged"
(:func:`nurbs_core.status.reported_status`). The checks, on the measures of
:func:`nurbs_core.patches.measures.network_quality`:

* the G1 seams' 99th percentile angle above ``WARN_SEAM`` (creased seams);
* a G1 seam turning by more than ``WARN_SEAM_MAX`` anywhere: one fold or unfollowed edge hides
  under a small percentile (the scanned bunny's pleat: 126.6 degrees at its worst, p99 1.14).
  Seams on a crease the engine found in the scan are G0 by design and not measured here;
* a patch folded over itself (a pleat: :func:`nurbs_core.patches.measures.fold_samples`), which
  has too little area for the flipped-area check;
* more than ``WARN_FLIPPED`` of the area facing inward;
* surface far from every point (``WARN_FAR`` of the area: a part the scan does not hold);
* points farther from the network on average than ``WARN_NOISE`` noise sigmas.
"""

from __future__ import annotations

import numpy as np

from nurbs_core.patches.defaults import WARN_SEAM, WARN_SEAM_MAX
from nurbs_core.patches.measures import NetworkQuality
from nurbs_core.status import WARN_FLIPPED

#: The share of the area far from every point (:func:`nurbs_core.patches.measures.far_limit`)
#: above which a warning is given.
WARN_FAR = 0.005
#: Mean point-to-network distance, in estimated noise sigmas, above which a warning is given
#: (pure noise averages 0.8 sigma; a clean fit of a scan measures 0.9, a watertight STL's
#: tessellation 1.9; a network whose layout passed the scanned bunny's ears by, 2.9-3.9; the
#: coarsened layout that follows them, about 2.3).
WARN_NOISE = 2.5
#: Folded patches named in a warning at most.
NAMED_PATCHES = 5


def network_warnings(quality: NetworkQuality, noise: float) -> list[str]:
    """The plain-language warnings the measures ``quality`` of a network call for (empty when
    every check holds); ``noise``: the cloud's estimated noise sigma (0: not checked)."""
    warnings = []
    seam = quality.seam
    if seam.p99 > WARN_SEAM:
        warnings.append(f"seams are not tangent everywhere: 99th percentile angle "
                        f"{seam.p99:.1f} degrees")
    if seam.max > WARN_SEAM_MAX:
        warnings.append(f"a seam turns by {seam.max:.0f} degrees at its worst (over "
                        f"{WARN_SEAM_MAX:.0f}, where the seams' 99th percentile is "
                        f"{seam.p99:.1f}): a fold or an edge the network does not follow")
    if quality.folds is not None and quality.folded_patches:
        folded = np.flatnonzero(quality.folds).tolist()
        named = ", ".join(str(p) for p in folded[:NAMED_PATCHES])
        more = len(folded) - NAMED_PATCHES
        named += f" and {more} more" if more > 0 else ""
        which = (f"patches {named} fold over themselves" if quality.folded_patches > 1
                 else f"patch {named} folds over itself")
        warnings.append(f"{which} ({quality.fold_samples} samples on a pleat, where the surface "
                        "turns back)")
    if quality.flipped_fraction > WARN_FLIPPED:
        warnings.append(f"{quality.flipped_fraction:.1%} of the area faces inward (folds)")
    if quality.far_fraction > WARN_FAR:
        warnings.append(f"{quality.far_fraction:.1%} of the surface lies farther than "
                        f"{quality.far_limit:.3g} from every point (up to {quality.s2c_max:.3g}, "
                        f"{quality.s2c_max / max(quality.diagonal, 1e-300):.1%} of the diagonal): "
                        "a part the scan does not hold")
    if noise > 0 and quality.c2s_mean > WARN_NOISE * noise:
        warnings.append(f"the points lie {quality.c2s_mean / noise:.1f} noise sigmas from the "
                        f"network on average (noise about {noise:.3g}): details finer than its "
                        "patches (thin parts, creases) are smoothed over")
    return warnings


def thin_scan_note(between: float, cell: float) -> str | None:
    """Why the network of an open scan whose mesh runs between two sides of it
    (:attr:`nurbs_core.patches.scan_mesh.ScanMesh.between`: the points' median distance to the
    mesh, 0 when it follows them) folds; None when the mesh follows the points."""
    if between <= 0.0:
        return None
    return (f"the points lie in two layers either side of the reconstructed mesh (median "
            f"distance {between:.3g}, {between / cell:.2f} of its cells): a part thinner than the "
            "reconstruction resolves (like a wing's skins) is one sheet between its two sides, "
            "which the fit pulls both ways")
