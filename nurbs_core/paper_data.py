"""Where the NURBS-Diff paper's data set (``shared/data/nurbsdiff_paper``) is on this machine.

The tests, the benchmarks and the documentation's screenshots read the paper's scans, valve
leaflets and multi-patch surfaces from it; the package does not ship them. The folder is found,
in this order, at ``$NURBS_STUDIO_DATA/nurbsdiff_paper`` or as ``shared/data/nurbsdiff_paper``
beside any folder above the given start (a checkout next to ``shared/``). No machine's absolute
path is written here: a checkout elsewhere sets ``NURBS_STUDIO_DATA`` (``.ci/run`` does).
"""

from __future__ import annotations

import os
from pathlib import Path

#: the environment variable naming the folder that holds ``nurbsdiff_paper``
DATA_VARIABLE = "NURBS_STUDIO_DATA"
_PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def paper_data_dir(start: Path | None = None) -> Path | None:
    """The ``nurbsdiff_paper`` folder, or None when it is not on this machine.

    ``start`` is where the search upwards for a ``shared/data`` folder begins (the checkout
    holding this package by default)."""
    env = os.environ.get(DATA_VARIABLE)
    candidates = [Path(env)] if env else []
    origin = (start or _PACKAGE_ROOT).resolve()
    candidates += [parent / "shared" / "data" for parent in (origin, *origin.parents)]
    for candidate in candidates:
        if (candidate / "nurbsdiff_paper").is_dir():
            return candidate / "nurbsdiff_paper"
    return None
