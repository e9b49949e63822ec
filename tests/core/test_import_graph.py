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


def test_no_package_of_the_engine_imports_itself_back(graph):
    """Read as packages (nurbs_core.fitting, nurbs_core.io, ... and the top-level modules),
    the graph has no loop either: a loop of packages is an import that runs back up a layer even
    when no single module closes it (fitting -> learn -> io -> trim -> fitting did)."""
    def package(module: str) -> str:
        return ".".join(module.split(".")[:2])

    imports: dict[str, set[str]] = {}
    for m in graph.modules:
        for i in graph.find_modules_directly_imported_by(m):
            if package(m) != package(i):
                imports.setdefault(package(m), set()).add(package(i))

    def reaches(start: str, goal: str) -> bool:
        seen, todo = set(), [start]
        while todo:
            here = todo.pop()
            if here == goal:
                return True
            if here not in seen:
                seen.add(here)
                todo.extend(imports.get(here, ()))
        return False

    back = sorted(f"{a} -> {b}" for a, targets in imports.items() for b in targets if reaches(b, a))
    assert not back, back
