"""No import cycles among the package's modules: every import counts, at the top, inside a function or under
`TYPE_CHECKING` (a type-only import still ties the two modules' meanings together).

`from package import name` imports the module `package.name` when there is one, else the package itself;
`import a.b.c` imports `a.b.c`. The implicit import of a module's parent packages is not counted: a package's
`__init__` may gather names from its own modules without making each of them a cycle with it.
"""
from __future__ import annotations

from pathlib import Path

from tests.test_layers import ALL, import_statements

def imported(module: str, path: Path) -> set[str]:
    """The package's modules `module` imports (see the module's note)."""
    found: set[str] = set()
    for source, names in import_statements(module, path.read_text(), path.name == "__init__.py"):
        if not names:  # `import a.b`
            found.add(source)
        found.update(f"{source}.{name}" if f"{source}.{name}" in ALL else source for name in names)
    return {name for name in found if name in ALL and name != module}


GRAPH = {module: imported(module, path) for module, path in ALL.items()}


def cycles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[frozenset[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, targets = work[-1]
            for target in targets:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(graph[target]))))
                    break
                if target in on_stack:
                    low[node] = min(low[node], index[target])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = set()
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.add(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(frozenset(component))
    return found


def path_through(component: frozenset[str]) -> list[str]:
    """One cycle inside `component`, as the chain of imports that closes it."""
    start = min(component)
    trail, seen, node = [start], {start}, start
    while True:
        node = min(t for t in GRAPH[node] if t in component)
        trail.append(node)
        if node in seen:
            return trail[trail.index(node):]
        seen.add(node)


def test_no_module_imports_itself_through_others():
    found = cycles(GRAPH)
    assert found == [], "\n".join(" -> ".join(path_through(c)) for c in found)


def test_the_search_finds_a_cycle_and_a_type_only_import(tmp_path):
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [frozenset({"a", "b", "c"})]
    path = tmp_path / "process.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import errors\n\n\n"
                    "def run():\n    from planhrc.planner import validate\n")
    assert imported("planhrc.planner.process", path) == {"planhrc.planner.errors", "planhrc.planner.validate"}
