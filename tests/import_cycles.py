"""The import cycles of packages, as grimp reads their source (every import, also inside
functions and under TYPE_CHECKING): the tests that keep the import graph a tree share it."""

from __future__ import annotations


def import_cycles(*packages: str) -> list[str]:
    """Each import that some chain of imports leads back from, as 'a -> ... -> a'."""
    import grimp

    graph = grimp.build_graph(*packages)
    cycles = []
    for module in sorted(graph.modules):
        for imported in graph.find_modules_directly_imported_by(module):
            if imported != module and graph.chain_exists(importer=imported, imported=module):
                chain = graph.find_shortest_chain(importer=imported, imported=module)
                cycles.append(" -> ".join((module, *chain)))
    return cycles
