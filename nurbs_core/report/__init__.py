"""Deviation reports: how far a scan lies from what was fitted to it, for a customer or a file.

* :mod:`nurbs_core.report.deviation` -- signed distances of points to a triangle mesh (the
  fitted surface, network or solid tessellated), tolerance bands and their statistics;
* :mod:`nurbs_core.report.document` -- the report itself: views from several sides, the
  histogram, statistics, the fit's settings and units, as one self-contained HTML file or a PDF
  (matplotlib, no display needed).

``nurbs-fit scan.xyz -o fit.step --report report.html`` writes one.
"""
