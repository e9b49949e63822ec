"""The VTK viewport (pyvistaqt); scene updates happen in place, on the GUI thread only."""
