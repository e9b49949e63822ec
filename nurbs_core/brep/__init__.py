"""Scanned machined parts as valid solids with exact analytic faces (the ``cad`` extra).

* :mod:`~nurbs_core.brep.primitives`: planes, spheres, cylinders and cones: distances, normals,
  candidates from minimal samples, least-squares refinement;
* :mod:`~nurbs_core.brep.segment`: the scan split into regions on those surfaces (efficient
  RANSAC with connected regions and the simplest type that fits);
* :mod:`~nurbs_core.brep.solid`: the solid as the union of the surfaces' arrangement cells that
  lie inside the scan (OpenCASCADE), sharp edges exact;
* :mod:`~nurbs_core.brep.part`: the route's test (:func:`~nurbs_core.brep.part.part_like`), the
  fit (:func:`~nurbs_core.brep.part.fit_part`) and its measures per face, and the solid of
  edited regions (:func:`~nurbs_core.brep.part.rebuild_part`);
* :mod:`~nurbs_core.brep.face_edits`: the user's edits of the regions (merge, split, a type
  forced), refitted by least squares and kept as a list that replays;
* :mod:`~nurbs_core.brep.occ`: OpenCASCADE helpers (faces, types, triangulation, validity);
* :mod:`~nurbs_core.brep.sample_parts`: parts made with OpenCASCADE, scanned with face labels.

``nurbs_core.route`` sends a closed, part-like scan here; ``nurbs-fit --part`` forces it and
``--no-part`` turns it off. numpy + scipy, and OCP where a solid is built.
"""
