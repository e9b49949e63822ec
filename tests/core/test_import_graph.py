"""The engine's import graph (every import, also inside functions, as grimp reads the source):
no module of nurbs_core reaches itself again through other modules, and the command line is a
leaf that no module imports. The layers are checked by lint-imports (pyproject.toml)."""

from __future__ import annotations

import pytest

grimp = pytest.importorskip("grimp")


@pytest.fixture(scope="module")
def graph():
    return grimp.build_graph("nurbs_core")


def test_no_module_of_the_engine_imports_itself_back():
    from import_cycles import import_cycles

    cycles = import_cycles("nurbs_core")
    assert not cycles, "\n".join(cycles)


def test_the_command_line_is_a_leaf(graph):
    assert graph.find_modules_that_directly_import("nurbs_core.cli") == set()
