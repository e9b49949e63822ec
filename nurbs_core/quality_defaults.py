"""The neighbourhood the quality report judges a cloud's points by (:mod:`nurbs_core.quality`).

Its own small module at the bottom of the layers so that what depends on it, such as the
fewest points a surface fit takes (:mod:`nurbs_core.fitting.normalised`), reads it without
importing the measures (scipy's trees, foot points, normals).
"""

from __future__ import annotations

#: neighbours of the local frames (normals, area per point, smoothing of the multiplicity): the
#: quality report judges each point among this many others
NEIGHBOURS = 12
