"""Scan to surface mesh: what the scan's topology really is, before any route acts on it.

* ``wrap``    the outside of a closed object's cloud as a voxel region that tolerates uneven
              sampling (each point closes a gap as wide as its own neighbourhood), and normals
              oriented against it (not propagated over a mesh that may invent handles)
"""
