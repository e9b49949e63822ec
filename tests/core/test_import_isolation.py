"""The engine is a pure library: importing it and its modules loads no GUI stack."""

from __future__ import annotations

import subprocess
import sys

FORBIDDEN = ("PySide6", "PyQt5", "PyQt6", "qtpy", "vtk", "vtkmodules", "pyvista", "pyvistaqt",
             "superqt", "pyqtgraph", "app")


def _run(code: str, timeout: float) -> str:
    """The stdout of ``code`` run in a fresh interpreter (which must exit 0)."""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=timeout)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_import_nurbs_core_loads_no_qt_or_vtk():
    code = (
        "import importlib, pkgutil, sys\n"
        "import nurbs_core\n"
        "for info in pkgutil.walk_packages(nurbs_core.__path__, 'nurbs_core.'):\n"
        "    if info.name != 'nurbs_core.cli':\n"
        "        importlib.import_module(info.name)\n"
        f"bad = sorted(m for m in sys.modules if m.split('.')[0] in {FORBIDDEN!r})\n"
        "print(','.join(bad))\n"
    )
    imported = _run(code, 300).strip()
    assert imported == "", f"nurbs_core imported GUI modules: {imported}"


def test_closed_networks_and_parts_fit_and_save_without_torch(tmp_path):
    """The routes that never differentiate (the closed network on numpy and scipy, the part on
    OpenCASCADE) and their writers do not load torch: its import is seconds of a fit."""
    import numpy as np

    from nurbs_core import samples

    head = tmp_path / "head.xyz"
    np.savetxt(head, samples.head(3000, seed=1, truth_count=20_000).points)
    import importlib.util

    suffixes = [".json", ".3dm", ".stl"] + ([".step"] if importlib.util.find_spec("OCP") else [])
    outputs = [str(tmp_path / f"head{suffix}") for suffix in suffixes]
    code = (
        "import sys\n"
        "from nurbs_core.cli import main\n"
        f"status = main([{str(head)!r}, '-o', *{outputs!r}, '-q'])\n"
        "print(status, 'torch' in sys.modules)\n"
    )
    printed = _run(code, 600)
    assert printed.split()[-2:] == ["0", "False"], printed


def test_the_fewest_points_of_a_surface_fit_are_read_without_the_quality_measures():
    """``fitting.normalised`` (every fit's first step) needs only the quality report's
    neighbourhood size, not its measures: importing it loads neither ``nurbs_core.quality`` nor
    scipy's trees (on main it loaded 599 modules, 202 without them)."""
    code = (
        "import sys\n"
        "from nurbs_core.fitting.normalised import MIN_SURFACE_POINTS\n"
        "from nurbs_core.quality_defaults import NEIGHBOURS\n"
        "print(MIN_SURFACE_POINTS == NEIGHBOURS + 1, 'nurbs_core.quality' in sys.modules,\n"
        "      'scipy.spatial' in sys.modules)\n"
    )
    assert _run(code, 120).split() == ["True", "False", "False"]
