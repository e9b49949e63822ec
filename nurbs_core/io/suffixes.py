"""Which suffixes each kind of result can be written as (and NURBS geometry read from): the
tables the writers, the output checks and the front ends share. Plain tuples, no imports."""

#: CAD exchange formats (OpenCASCADE: the ``cad`` extra).
CAD_SUFFIXES = (".step", ".stp", ".iges", ".igs")
#: Files that hold NURBS curves and surfaces (:func:`nurbs_core.io.load`); OpenCASCADE's own
#: ``.brep`` (what a fitted solid is also written as) is read, its faces as surfaces, like STEP.
NURBS_SUFFIXES = (".3dm", ".json", ".dat", ".smesh", *CAD_SUFFIXES, ".brep")
#: What a patch network can be saved as (:func:`nurbs_core.io.network_io.write_network`).
NETWORK_SUFFIXES = (".json", ".3dm", ".step", ".stp", ".iges", ".igs", ".obj", ".ply", ".stl",
                    ".glb")
#: What a single fitted curve or surface can be saved as (:func:`nurbs_core.io.save`).
EXPORT_SUFFIXES = (".3dm", ".step", ".stp", ".iges", ".igs", ".json", ".obj", ".stl", ".ply",
                   ".glb", ".csv", ".dat")
