"""The packages form one-way layers: no module imports a layer above its own, no two modules
import each other, only the scripts import the command lines, and the robot and the person know
nothing of the envs.

| layer | packages | may import |
| --- | --- | --- |
| 0, bottom | ``handover_env`` (simulator, data, feature encoders) | itself |
| 1, middle | ``agents``, ``baselines`` | layers 0-1 |
| 2, top | ``handover_eval`` (evaluation, CLIs, demo), ``train.py``, ``evaluate.py`` | layers 0-2 |

Every import counts, at module level or inside a function (a lazy import is still a dependency),
read from the source with :mod:`ast`, so nothing is executed; only imports under
``if TYPE_CHECKING:`` (annotations, never run) are left out of the module graph.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = {"handover_env": 0, "agents": 1, "baselines": 1, "handover_eval": 2}
SCRIPTS = {"train.py": 2, "evaluate.py": 2}
#: A module longer than this says why in its docstring ("... over 500 lines because ...").
MAX_LINES = 500


def _sources() -> list[tuple[Path, int]]:
    files = [
        (p, layer) for pkg, layer in LAYERS.items() for p in sorted((ROOT / pkg).rglob("*.py"))
    ]
    return files + [(ROOT / name, layer) for name, layer in SCRIPTS.items()]


def imported_packages(path: Path) -> set[tuple[str, int]]:
    """(top-level package, line) of every absolute import in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {(alias.name.split(".")[0], node.lineno) for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add((node.module.split(".")[0], node.lineno))
    return found


def test_every_package_is_in_a_layer():
    packages = {p.parent.name for p in ROOT.glob("*/__init__.py")}
    assert packages - {"tests"} == set(LAYERS)


@pytest.mark.parametrize(
    "path, layer", _sources(), ids=lambda v: str(v.relative_to(ROOT)) if isinstance(v, Path) else ""
)
def test_no_module_imports_a_layer_above_its_own(path, layer):
    above = sorted(f"{pkg} (line {line})" for pkg, line in imported_packages(path)
                   if LAYERS.get(pkg, -1) > layer)
    assert not above, f"{path.relative_to(ROOT)} (layer {layer}) imports a layer above it: {above}"


def test_the_checker_sees_lazy_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text(
        "import numpy\ndef g():\n    from handover_eval.methods import METHODS\n    import "
        "agents.base\n"
    )
    assert {pkg for pkg, _ in imported_packages(f)} == {"numpy", "handover_eval", "agents"}


# ---------------------------------------------------------------------- the module graph
def module_name(path: Path, root: Path = ROOT) -> str:
    """``handover_env/envs/base_handover.py`` -> ``handover_env.envs.base_handover``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of the import nodes inside ``if TYPE_CHECKING:`` blocks."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            name = test.attr if isinstance(test, ast.Attribute) else getattr(test, "id", None)
            if name == "TYPE_CHECKING":
                skip |= {id(n) for child in node.body for n in ast.walk(child)}
    return skip


def imported_modules(path: Path, known: set[str], root: Path = ROOT) -> set[str]:
    """The first-party modules ``path`` imports, at module level or in a function (not under
    ``TYPE_CHECKING``). ``from a.b import c`` is the module ``a.b.c`` when there is one, else
    ``a.b``; a name that is not a module resolves to the module holding it; relative imports are
    resolved against the file's package."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    skip = _type_checking_nodes(tree)
    me = module_name(path, root)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                anchor = parts[: len(parts) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                     for a in node.names]
        else:
            continue
        for name in names:
            while name and name not in known:
                name = name.rpartition(".")[0]
            if name and name != me:
                found.add(name)
    return found


def private_imports(path: Path) -> list[str]:
    """``"module._name"`` for every private name ``path`` imports from another module."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    return sorted(
        f"{node.module or '.'}.{alias.name}"
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
        if alias.name.startswith("_") and not alias.name.startswith("__")
    )


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` as ``[a, b, ..., a]`` (any length), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    stack: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                return stack[stack.index(w):] + [w]
            if w not in state and (cycle := visit(w)):
                return cycle
        stack.pop()
        state[v] = 2
        return None

    for v in sorted(graph):
        if v not in state and (cycle := visit(v)):
            return cycle
    return None


def import_graph(root: Path = ROOT, packages: tuple[str, ...] = tuple(LAYERS)) -> dict:
    """{module: the first-party modules it imports} over ``packages`` under ``root``."""
    files = [p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))]
    known = {module_name(p, root) for p in files}
    return {module_name(p, root): imported_modules(p, known, root) for p in files}


def mutual_imports(graph: dict[str, set[str]]) -> list[str]:
    """``"a <-> b"`` for every pair of modules that import each other."""
    return sorted(f"{a} <-> {b}" for a, deps in graph.items() for b in deps
                  if a < b and a in graph.get(b, set()))


def cli_importers(graph: dict[str, set[str]]) -> list[str]:
    """Modules outside ``handover_eval.cli`` that import it (the scripts are not in the graph)."""
    return sorted(f"{m} imports {d}" for m, deps in graph.items() for d in deps
                  if d.split(".")[:2] == ["handover_eval", "cli"]
                  and m.split(".")[:2] != ["handover_eval", "cli"])


def env_importers_below(graph: dict[str, set[str]]) -> list[str]:
    """Modules of ``handover_env.robot`` or ``handover_env.person`` that import ``envs``."""
    return sorted(f"{m} imports {d}" for m, deps in graph.items() for d in deps
                  if m.split(".")[:2] in (["handover_env", "robot"], ["handover_env", "person"])
                  and d.split(".")[:2] == ["handover_env", "envs"])


def test_no_two_modules_import_each_other():
    graph = import_graph()
    assert mutual_imports(graph) == []
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])


def test_no_private_name_is_imported_across_modules():
    files = [p for pkg in LAYERS for p in sorted((ROOT / pkg).rglob("*.py"))]
    files += sorted((ROOT / "tests").glob("*.py")) + sorted((ROOT / "bench").glob("*.py"))
    shared = {str(p.relative_to(ROOT)): names for p in files if (names := private_imports(p))}
    assert not shared, f"private names imported from other modules: {shared}"


@pytest.mark.parametrize("pkg", [*LAYERS, "bench"])
def test_long_modules_say_why(pkg):
    long = {}
    for path in sorted((ROOT / pkg).rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        doc = ast.get_docstring(ast.parse(text)) or ""
        if len(text.splitlines()) > MAX_LINES and f"over {MAX_LINES} lines" not in doc:
            long[str(path.relative_to(ROOT))] = len(text.splitlines())
    assert not long, f"modules over {MAX_LINES} lines whose docstring does not say why: {long}"


def test_nothing_outside_the_cli_imports_it():
    assert cli_importers(import_graph()) == []


def test_the_robot_and_the_person_do_not_import_the_envs():
    graph = import_graph()
    assert any(m.startswith("handover_env.robot.") for m in graph)
    assert any(m.startswith("handover_env.person.") for m in graph)
    assert env_importers_below(graph) == []


def test_no_two_classes_share_a_name():
    seen: dict[str, list[str]] = {}
    for pkg in LAYERS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef):
                    seen.setdefault(node.name, []).append(str(path.relative_to(ROOT)))
    twins = {name: where for name, where in seen.items() if len(where) > 1}
    assert not twins, f"one name per idea: {twins}"


def _tree(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_each_rule_fails_on_a_crafted_violation(tmp_path):
    pkg = ("handover_env", "handover_eval")
    inits = {f"{p}/__init__.py": "" for p in (
        "handover_env", "handover_env/robot", "handover_env/person", "handover_env/envs",
        "handover_eval", "handover_eval/cli")}
    root = _tree(tmp_path, {
        **inits,
        # a circle hidden in a function, and one through a relative import
        "handover_env/robot/a.py": "def f():\n    from handover_env.robot import b\n",
        "handover_env/robot/b.py": "from .a import f\n",
        # a TYPE_CHECKING import is not a dependency
        "handover_env/person/c.py": (
            "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
            "    from handover_env.person.d import X\n"),
        "handover_env/person/d.py": "from handover_env.person.c import Y\n",
        # the person importing the envs; a library module importing the CLI
        "handover_env/person/e.py": "import handover_env.envs.base\n",
        "handover_env/envs/base.py": "",
        "handover_eval/run.py": "from handover_eval.cli.args import int_in_range\n",
        "handover_eval/cli/args.py": "",
        "handover_eval/cli/main.py": "from handover_eval.cli import args\n",
    })
    graph = import_graph(root, pkg)
    assert mutual_imports(graph) == ["handover_env.robot.a <-> handover_env.robot.b"]
    assert find_cycle(graph) == ["handover_env.robot.a", "handover_env.robot.b",
                                 "handover_env.robot.a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert private_imports(root / "handover_env/robot/b.py") == []
    (root / "handover_eval/leak.py").write_text("from handover_eval.run import _secret, __all__\n")
    assert private_imports(root / "handover_eval/leak.py") == ["handover_eval.run._secret"]
    assert cli_importers(graph) == ["handover_eval.run imports handover_eval.cli.args"]
    assert env_importers_below(graph) == [
        "handover_env.person.e imports handover_env.envs.base"]
