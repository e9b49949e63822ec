"""Fitting NURBS curves and surfaces to points; the public names live in :mod:`nurbs_core.fit`."""
