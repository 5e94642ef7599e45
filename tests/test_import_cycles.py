"""No module of dyntarget imports, directly or through others, a module that imports it back.

The import graph is grimp's (the library import-linter checks the layers with); the cycles are
its strongly connected components of more than one module, found by Tarjan's algorithm here.
Imports only made for the type checker (``if TYPE_CHECKING:``) are not imports at run time.
"""

from __future__ import annotations

import pytest

grimp = pytest.importorskip("grimp")


def _cycles(graph) -> list[list[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.find_modules_directly_imported_by(v):
            if not w.startswith("dyntarget"):
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    return found


def test_the_cycle_finder_finds_a_two_module_cycle():
    class Graph:  # a <-> b, b -> c: one cycle {a, b}
        modules = ("dyntarget.a", "dyntarget.b", "dyntarget.c")
        edges = (
            ("dyntarget.a", "dyntarget.b"),
            ("dyntarget.b", "dyntarget.a"),
            ("dyntarget.b", "dyntarget.c"),
        )

        def find_modules_directly_imported_by(self, m):
            return {b for a, b in self.edges if a == m}

    assert _cycles(Graph()) == [["dyntarget.a", "dyntarget.b"]]


def test_dyntarget_has_no_import_cycle():
    graph = grimp.build_graph("dyntarget", exclude_type_checking_imports=True)
    assert _cycles(graph) == []
