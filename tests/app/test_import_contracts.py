"""The import contracts in pyproject.toml ([tool.importlinter], run by .ci/run) hold for the tree
and break when a forbidden import is added (checked on a copy of the packages)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LINT = Path(sys.executable).with_name("lint-imports")


def _copy(tmp_path: Path) -> Path:
    ignore = shutil.ignore_patterns("__pycache__")
    for package in ("nurbs_core", "app"):
        shutil.copytree(ROOT / package, tmp_path / package, ignore=ignore)
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    return tmp_path


def _lint(tree: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(LINT)], cwd=tree, capture_output=True, text=True, timeout=300)


@pytest.mark.skipif(not LINT.exists(), reason="import-linter is not installed")
@pytest.mark.parametrize("module, line, broken", [
    ("app/panels/knot_panel.py", "import torch", "app.panels is not allowed to import torch"),
    ("app/viewport/scene.py", "from nurbs_core.fitting import engine",
     "app.viewport is not allowed to import nurbs_core"),
    ("nurbs_core/losses.py", "import PySide6", "nurbs_core is not allowed to import PySide6"),
    ("nurbs_core/fitting/config.py", "import torch",
     "nurbs_core.fitting.config is not allowed to import torch"),
    ("nurbs_core/batch/worker.py", "from nurbs_core.cli import main",
     "nurbs_core.batch is not allowed to import nurbs_core.cli"),
    ("nurbs_core/jobs/report.py", "import nurbs_core.batch",
     "nurbs_core.jobs is not allowed to import nurbs_core.batch"),
    ("nurbs_core/geometry.py", "from nurbs_core.fitting import fit",
     "nurbs_core.geometry is not allowed to import nurbs_core.fitting"),
    ("nurbs_core/surfacing/core.py", "from nurbs_core.geometry import NurbsSurface",
     "nurbs_core.surfacing.core is not allowed to import torch"),
    ("nurbs_core/quality.py", "from nurbs_core.fitting.projection import project",
     "nurbs_core.quality is not allowed to import torch"),
])
def test_the_contracts_hold_and_break_on_a_forbidden_import(tmp_path, module, line, broken):
    tree = _copy(tmp_path)
    clean = _lint(tree)
    assert clean.returncode == 0 and "6 kept, 0 broken" in clean.stdout, clean.stdout[-2000:]
    with open(tree / module, "a") as handle:
        handle.write(f"\n{line}\n")
    result = _lint(tree)
    assert result.returncode != 0 and broken in result.stdout, result.stdout[-2000:]


def test_no_module_of_the_app_or_the_engine_imports_itself_back():
    # the window's parts take protocols (app.window.hosts), not the window
    pytest.importorskip("grimp")
    from import_cycles import import_cycles

    cycles = import_cycles("app", "nurbs_core")
    assert not cycles, "\n".join(cycles)
