"""Dock panels: controls that show the document and turn user input into settings edits."""
