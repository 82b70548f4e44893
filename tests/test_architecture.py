"""The package's folders are its layers (docs/development.md, "Layout"): apps > reference > io > engine > model,
each importing only those below it, and the product (model, engine, io) never importing the
reference stack. The contracts live in setup.cfg ([importlinter]); import-linter checks them here,
on every import (deferred imports inside functions too), so an import that runs back up fails CI.
Import circles are looked for separately: a layers contract allows them within a layer."""
from __future__ import annotations

from pathlib import Path

import grimp
from importlinter.cli import lint_imports

REPO = Path(__file__).resolve().parent.parent


def test_the_layer_contracts_hold(monkeypatch):
    monkeypatch.chdir(REPO)  # lint-imports reads setup.cfg from the working folder
    assert lint_imports(config_filename=str(REPO / "setup.cfg")) == 0


def test_no_module_imports_itself_through_others():
    """No circle of imports between pyclray's modules: every strongly connected component of the
    module graph is one module (a package's __init__ and the modules it hands names on from are
    one face, so imports of a package's own __init__ by its modules are the only ones allowed)."""
    graph = grimp.build_graph("pyclray", include_external_packages=False)
    modules = sorted(graph.modules)
    edges = {m: {n for n in graph.find_modules_directly_imported_by(m) if not m.startswith(n + ".")} for m in modules}
    # Tarjan's strongly connected components
    index, low, stack, on, circles, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for module in modules:
        if module not in index:
            visit(module)
    assert not circles, circles
