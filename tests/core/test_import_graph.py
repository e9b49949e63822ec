"""The engine's import graph (every import, also inside functions, as grimp reads the source):
no module of nurbs_core reaches itself again through other modules, and the command line is a
leaf that no module imports. The layers are checked by lint-imports (pyproject.toml)."""

from __future__ import annotations

import pytest

grimp = pytest.importorskip("grimp")


@pytest.fixture(scope="module")
def graph():
    return grimp.build_graph("nurbs_core")


def test_no_module_of_the_engine_imports_itself_back(graph):
    cycles = []
    for module in sorted(graph.modules):
        for imported in graph.find_modules_directly_imported_by(module):
            if imported != module and graph.chain_exists(importer=imported, imported=module):
                chain = graph.find_shortest_chain(importer=imported, imported=module)
                cycles.append(" -> ".join((module, *chain)))
    assert not cycles, "\n".join(cycles)


def test_the_command_line_is_a_leaf(graph):
    assert graph.find_modules_that_directly_import("nurbs_core.cli") == set()
