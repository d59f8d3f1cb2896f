"""The packages form one-way layers: no module imports a layer above its own, no two modules
import each other, only the scripts import the command lines, and the robot and the person know
nothing of the envs.

| layer | packages | may import |
| --- | --- | --- |
| 0, bottom | ``handover_env`` (simulator, data, feature encoders) | itself |
| 1, middle | ``agents``, ``baselines`` | layers 0-1 |
| 2, top | ``handover_eval`` (evaluation, CLIs, demo), ``train.py``, ``evaluate.py`` | layers 0-2 |

Inside ``handover_env`` the folders import one way too (:data:`SIMULATOR_FOLDERS`): ``envs`` ->
``robot`` -> ``person`` -> ``data``, ``sensors`` -> the base modules (``config``, ``numbers``,
``regular_file``, ...); so ``data`` imports nothing of the person, the robot or the envs, and no
folder-level import runs back up. Nothing under ``handover_env`` imports ``argparse`` (the command
lines are ``handover_eval/cli``'s), and in ``handover_eval`` only :data:`FILE_WRITERS` open a file
for writing (every other module writes through ``handover_eval/reporting.py``).

Every import counts, at module level or inside a function (a lazy import is still a dependency),
read from the source with :mod:`ast`, so nothing is executed; only imports under
``if TYPE_CHECKING:`` (annotations, never run) are left out of the module graph.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAYERS = {"handover_env": 0, "agents": 1, "baselines": 1, "handover_eval": 2}
SCRIPTS = {"train.py": 2, "evaluate.py": 2}
#: A module longer than this says why in its docstring ("... over 500 lines because ...").
MAX_LINES = 500
#: The level of each folder of ``handover_env``; its top-level modules (the base modules) are
#: level 0. A folder imports only folders and modules of a lower level.
SIMULATOR_FOLDERS = {"envs": 4, "robot": 3, "person": 2, "data": 1, "sensors": 1}
#: The modules of ``handover_eval`` that open a file for writing themselves, and why. Checkpoint
#: files are written by ``baselines/checkpoint_io.py`` through ``handover_env/atomic_write.py``,
#: so ``handover_eval`` holds no checkpoint writer.
FILE_WRITERS = {
    "handover_eval/reporting.py": "the one atomic writer of each result format",
    "handover_eval/output_lock.py": "the lock file of an output folder, created and held open",
}


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
    """Modules outside ``handover_eval.cli`` that import it (the scripts are not in the graph; a
    package's ``__main__``, what ``python -m`` runs, is a script too)."""
    return sorted(f"{m} imports {d}" for m, deps in graph.items() for d in deps
                  if d.split(".")[:2] == ["handover_eval", "cli"]
                  and m.split(".")[:2] != ["handover_eval", "cli"]
                  and m.split(".")[-1] != "__main__")


def env_importers_below(graph: dict[str, set[str]]) -> list[str]:
    """Modules of ``handover_env.robot`` or ``handover_env.person`` that import ``envs``."""
    return sorted(f"{m} imports {d}" for m, deps in graph.items() for d in deps
                  if m.split(".")[:2] in (["handover_env", "robot"], ["handover_env", "person"])
                  and d.split(".")[:2] == ["handover_env", "envs"])


def unit_of(module: str, package: str) -> str | None:
    """The direct part of ``package`` (a subpackage or a module; ``__init__`` for the package's
    own) that holds ``module``, None if ``module`` is outside ``package``."""
    parts, prefix = module.split("."), package.split(".")
    if parts[: len(prefix)] != prefix:
        return None
    return parts[len(prefix)] if len(parts) > len(prefix) else "__init__"


def folder_edges(graph: dict[str, set[str]], package: str) -> set[tuple[str, str]]:
    """``(a, b)`` for every two distinct parts of ``package`` where a module of ``a`` imports one
    of ``b``."""
    return {(a, b) for m, deps in graph.items() if (a := unit_of(m, package)) is not None
            for d in deps if (b := unit_of(d, package)) is not None and b != a}


def back_arrows(edges: set[tuple[str, str]]) -> list[str]:
    """``"a -> b"`` for every edge whose end reaches its start again (an edge of a circle)."""
    out: dict[str, set[str]] = {}
    for a, b in edges:
        out.setdefault(a, set()).add(b)

    def reaches(start: str, goal: str) -> bool:
        seen, todo = {start}, [start]
        while todo:
            for w in out.get(todo.pop(), ()):
                if w == goal:
                    return True
                if w not in seen:
                    seen.add(w)
                    todo.append(w)
        return False

    return sorted(f"{a} -> {b}" for a, b in edges if reaches(b, a))


def simulator_layer_problems(graph: dict[str, set[str]], root: Path = ROOT) -> list[str]:
    """Folders of ``handover_env`` not in :data:`SIMULATOR_FOLDERS`, and folder-level imports that
    do not run down its levels (a base module importing another is level 0 to 0, allowed)."""
    folders = {p.parent.name for p in (root / "handover_env").glob("*/__init__.py")}
    problems = [f"handover_env/{f}/ has no level in SIMULATOR_FOLDERS" for f in
                sorted(folders - set(SIMULATOR_FOLDERS))]
    level = {**dict.fromkeys(folders, 99), **SIMULATOR_FOLDERS}
    for a, b in sorted(folder_edges(graph, "handover_env")):
        la, lb = level.get(a, 0), level.get(b, 0)
        if la <= lb and (la, lb) != (0, 0):
            problems.append(f"{a} (level {la}) imports {b} (level {lb})")
    return problems


def data_importers_above(graph: dict[str, set[str]]) -> list[str]:
    """Modules of ``handover_env.data`` that import the person, the robot or the envs."""
    return sorted(f"{m} imports {d}" for m, deps in graph.items() for d in deps
                  if m.split(".")[:2] == ["handover_env", "data"]
                  and d.split(".")[:2] in (["handover_env", "person"], ["handover_env", "robot"],
                                           ["handover_env", "envs"]))


def argparse_importers(root: Path = ROOT) -> list[str]:
    """``"path:line"`` of every import of ``argparse`` under ``handover_env/``."""
    return sorted(f"{p.relative_to(root)}:{line}" for p in sorted((root / "handover_env").rglob(
        "*.py")) for pkg, line in imported_packages(p) if pkg == "argparse")


#: Methods that write a file whatever they are called on (``reporting.write_text`` excepted).
_WRITING_METHODS = {"write_text", "write_bytes", "savefig"}
_TEMP_FILES = {"mkstemp", "NamedTemporaryFile", "TemporaryFile", "SpooledTemporaryFile"}
_NUMPY_SAVES = {"save", "savez", "savez_compressed", "savetxt"}
#: Module functions that write a file, by module.
_WRITING_FUNCTIONS = {"shutil": {"copy", "copy2", "copyfile", "copytree", "move"},
                      "tempfile": _TEMP_FILES, "torch": {"save"}, "np": _NUMPY_SAVES,
                      "numpy": _NUMPY_SAVES}


def file_writes(path: Path) -> list[str]:
    """``"call (line n)"`` for every place ``path`` opens a file for writing itself: ``open``,
    ``Path.open`` or ``os.fdopen`` with a mode that writes, appends, creates or updates (or a mode
    that is not a literal), any ``os.open`` (its flags are not read), the methods
    ``write_text``, ``write_bytes`` and ``savefig``, the temporary files of :mod:`tempfile`,
    ``shutil``'s copies and moves, ``torch.save`` and numpy's saves."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
        owner = getattr(func.value, "id", "") if isinstance(func, ast.Attribute) else ""
        if name in ("open", "fdopen"):
            if owner == "os" and name == "open":
                found.append(f"os.open (line {node.lineno})")
                continue
            at = 0 if isinstance(func, ast.Attribute) and owner not in ("os", "io") else 1
            mode = next((k.value for k in node.keywords if k.arg == "mode"),
                        node.args[at] if len(node.args) > at else ast.Constant("r"))
            if not (isinstance(mode, ast.Constant) and isinstance(mode.value, str)
                    and not set(mode.value) & set("wax+")):
                found.append(f"{name} (line {node.lineno})")
        elif (name in _WRITING_FUNCTIONS.get(owner, ()) or (name in _TEMP_FILES and not owner)
              or (name in _WRITING_METHODS and isinstance(func, ast.Attribute)
                  and owner != "reporting")):
            module = owner + "." if name in _WRITING_FUNCTIONS.get(owner, ()) else ""
            found.append(f"{module}{name} (line {node.lineno})")
    return sorted(found, key=lambda f: int(f.rsplit(" ", 1)[1].rstrip(")")))


def writers_outside_reporting(root: Path = ROOT) -> dict[str, list[str]]:
    """{module: its file writes} for the ``handover_eval`` modules not in :data:`FILE_WRITERS`."""
    files = sorted((root / "handover_eval").rglob("*.py"))
    return {rel: writes for p in files if (rel := str(p.relative_to(root))) not in FILE_WRITERS
            and (writes := file_writes(p))}


def test_no_two_modules_import_each_other():
    graph = import_graph()
    assert mutual_imports(graph) == []
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])


def test_no_private_name_is_imported_across_modules():
    files = [p for pkg in LAYERS for p in sorted((ROOT / pkg).rglob("*.py"))]
    files += sorted((ROOT / "tests").rglob("*.py")) + sorted((ROOT / "bench").glob("*.py"))
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


def test_the_simulator_folders_import_one_way():
    graph = import_graph()
    assert {"envs", "robot", "person", "data", "sensors"} <= {
        unit_of(m, "handover_env") for m in graph}
    assert simulator_layer_problems(graph) == []
    assert back_arrows(folder_edges(graph, "handover_env")) == []


def test_the_data_imports_nothing_of_the_person_the_robot_or_the_envs():
    graph = import_graph()
    assert any(m.startswith("handover_env.data.") for m in graph)
    assert data_importers_above(graph) == []


def test_nothing_under_handover_env_imports_argparse():
    assert argparse_importers() == []


def test_only_the_writers_open_files_for_writing_in_handover_eval():
    for rel in FILE_WRITERS:
        assert file_writes(ROOT / rel), f"{rel} is listed as a writer but opens no file to write"
    assert writers_outside_reporting() == {}


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


def test_each_simulator_and_writer_rule_fails_on_a_crafted_violation(tmp_path):
    pkg = ("handover_env", "handover_eval")
    inits = {f"{p}/__init__.py": "" for p in (
        "handover_env", "handover_env/data", "handover_env/person", "handover_env/robot",
        "handover_env/envs", "handover_env/sensors", "handover_env/gadgets", "handover_eval")}
    root = _tree(tmp_path, {
        **inits,
        # data importing the person, which imports the data: a folder-level circle
        "handover_env/data/rec.py": "def f():\n    from handover_env.person import walk\n",
        "handover_env/person/walk.py": "from handover_env.data.rec import f\n",
        # the robot reaching up into the envs; sensors importing data (same level)
        "handover_env/robot/arm.py": "import handover_env.envs.base\n",
        "handover_env/envs/base.py": "from handover_env import numbers, robot\n",
        "handover_env/sensors/cam.py": "from handover_env.data import rec\n",
        # base modules import each other and go down nowhere else: allowed
        "handover_env/numbers.py": "from handover_env.paths import P\n",
        "handover_env/paths.py": "",
        "handover_env/tool.py": "def main():\n    import argparse\n",
        "handover_eval/out.py": (
            "import os\nfrom pathlib import Path\nfrom handover_eval import reporting\n"
            "def f(p, fig, m):\n    open(p, 'w')\n    Path(p).open(mode='ab')\n"
            "    Path(p).write_text('x')\n    fig.savefig(p)\n    os.open(p, os.O_RDONLY)\n"
            "    open(p, m)\n"
            "    reporting.write_text('x', p)\n    open(p)\n    open(p, 'rb')\n"
            "    Path(p).open()\n    Path(p).read_text()\n    {}.copy()\n"
            "    np.save(p, 1)\n    shutil.copy(p, p)\n    mkstemp()\n"),
        "handover_eval/reporting.py": "def write_text(t, p):\n    open(p, 'w').write(t)\n",
        "handover_eval/output_lock.py": "import os\ndef lock(p):\n    os.open(p, os.O_CREAT)\n",
    })
    graph = import_graph(root, pkg)
    assert data_importers_above(graph) == [
        "handover_env.data.rec imports handover_env.person.walk"]
    assert back_arrows(folder_edges(graph, "handover_env")) == [
        "data -> person", "envs -> robot", "person -> data", "robot -> envs"]
    assert back_arrows({("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")}) == [
        "a -> b", "b -> c", "c -> a"]
    assert simulator_layer_problems(graph, root) == [
        "handover_env/gadgets/ has no level in SIMULATOR_FOLDERS",
        "data (level 1) imports person (level 2)",
        "robot (level 3) imports envs (level 4)",
        "sensors (level 1) imports data (level 1)",
    ]
    assert argparse_importers(root) == ["handover_env/tool.py:2"]
    assert writers_outside_reporting(root) == {"handover_eval/out.py": [
        "open (line 5)", "open (line 6)", "write_text (line 7)", "savefig (line 8)",
        "os.open (line 9)", "open (line 10)", "np.save (line 17)", "shutil.copy (line 18)",
        "mkstemp (line 19)"]}
