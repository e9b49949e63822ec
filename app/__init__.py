"""NURBS Studio desktop app: a thin PySide6 + pyvistaqt shell over :mod:`nurbs_core`."""

from __future__ import annotations

import os

# qtpy (used by pyvistaqt) must pick PySide6, never a stray PyQt
os.environ.setdefault("QT_API", "pyside6")
