"""The structure of the tree, counted from the code's own imports: units, layers and import edges.

The module graph is the layer test's own (:func:`test_layers.imported_modules`, every import at
module level or in a function, read with :mod:`ast`; ``TYPE_CHECKING`` imports left out). At a
level (the whole tree, or one package such as ``handover_env``), the **units** are its direct
parts: the subpackages and modules of a package (its ``__init__`` counts as one), or, for the
whole tree, the top-level packages, ``bench`` and the scripts ``train.py`` and ``evaluate.py``.
An **edge** ``a -> b`` is one pair of distinct units where some module in ``a`` imports some
module in ``b`` (:func:`test_layers.folder_edges`). A **back-arrow** is an edge inside an import
circle of units, ``a -> b`` while ``b`` reaches ``a`` (:func:`test_layers.back_arrows`). The
**layers** are the levels of the circle-free graph of units (each circle counted as one unit): a
unit that imports no other unit is in layer 1, any other unit one above the highest it imports.

    python bench/structure.py                       # this tree
    python bench/structure.py --root /path/to/tree  # another checkout (its own code, this script)
    python bench/structure.py --edges               # and every edge
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "project"))
from test_layers import (  # noqa: E402
    LAYERS,
    SCRIPTS,
    back_arrows,
    folder_edges,
    imported_modules,
    module_name,
)
from test_layers import unit_of as part_of  # noqa: E402

#: The packages reported one by one (besides the whole tree).
PACKAGES = ("handover_env", "handover_env.data", "handover_env.person", "handover_eval")


def module_graph(root: Path) -> dict[str, set[str]]:
    """{module: the first-party modules it imports} over the layered packages, ``bench`` and the
    scripts under ``root``."""
    files = [p for pkg in LAYERS for p in sorted((root / pkg).rglob("*.py"))]
    files += sorted((root / "bench").glob("*.py")) + [root / name for name in SCRIPTS]
    files = [p for p in files if p.is_file()]
    known = {module_name(p, root) for p in files}
    return {module_name(p, root): imported_modules(p, known, root) for p in files}


def unit_of(module: str, package: str | None) -> str | None:
    """The unit of ``package`` (None: the whole tree) that holds ``module``, None if outside."""
    return module.split(".")[0] if package is None else part_of(module, package)


def unit_edges(graph: dict[str, set[str]], package: str | None) -> set[tuple[str, str]]:
    """The edges between the units of ``package`` (None: the whole tree)."""
    if package is not None:
        return folder_edges(graph, package)
    return {(a, b) for m, deps in graph.items() for d in deps
            if (a := m.split(".")[0]) != (b := d.split(".")[0])}


def circles(units: Iterable[str], edges: set[tuple[str, str]]) -> list[set[str]]:
    """The strongly connected components of the unit graph (Tarjan), singletons included."""
    out: dict[str, set[str]] = {}
    for a, b in edges:
        out.setdefault(a, set()).add(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(out.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            found.append(component)

    for v in sorted(units):
        if v not in index:
            visit(v)
    return found


def layers(units: set[str], edges: set[tuple[str, str]]) -> dict[str, int]:
    """{unit: its layer} (module docstring; a circle's units share one layer)."""
    component = {u: i for i, c in enumerate(circles(units, edges)) for u in c}
    down: dict[int, set[int]] = {}
    for a, b in edges:
        if component[a] != component[b]:
            down.setdefault(component[a], set()).add(component[b])
    level: dict[int, int] = {}

    def height(c: int) -> int:
        if c not in level:
            level[c] = 1 + max((height(d) for d in down.get(c, ())), default=0)
        return level[c]

    return {u: height(component[u]) for u in units}


def describe(graph: dict[str, set[str]], package: str | None) -> dict:
    """Units, edges, back-arrows and layers of ``package`` (None: the whole tree)."""
    units = {u for m in graph if (u := unit_of(m, package)) is not None}
    edges = unit_edges(graph, package)
    back = back_arrows(edges)
    level = layers(units, edges)
    return {
        "units": sorted(units),
        "edges": sorted(edges),
        "back_arrows": back,
        "layers": max(level.values(), default=0),
        "by_layer": {n: sorted(u for u in units if level[u] == n)
                     for n in range(1, max(level.values(), default=0) + 1)},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1],
                        help="the tree to count (default: this one)")
    parser.add_argument("--edges", action="store_true", help="list every edge")
    args = parser.parse_args()
    graph = module_graph(args.root.resolve())
    print(f"tree: {args.root.resolve()} ({len(graph)} modules)")
    for package in (None, *PACKAGES):
        d = describe(graph, package)
        name = package or "whole tree"
        print(f"\n{name}: {len(d['units'])} units in {d['layers']} layers, "
              f"{len(d['edges'])} import edges, {len(d['back_arrows'])} back-arrows")
        for n, members in reversed(d["by_layer"].items()):
            print(f"  layer {n}: {' '.join(members)}")
        for arrow in d["back_arrows"]:
            print(f"  back-arrow: {arrow}")
        if args.edges:
            for a, b in d["edges"]:
                print(f"  {a} -> {b}")


if __name__ == "__main__":
    main()
