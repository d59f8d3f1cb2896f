"""The shape of ``handover_env``: no import circles, no private names shared across modules, no
long module without a stated reason, and tasks that return values instead of writing the env.

Imports are read from the source with :mod:`ast` (nothing is executed); an import inside a
function counts, one under ``if TYPE_CHECKING:`` does not (it never runs).
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import gymnasium as gym
import numpy as np

import handover_env  # noqa: F401  (registers the ids)
from agents.static import StaticAgent

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "handover_env"
MAX_LINES = 500


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


MODULES = _modules()


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            if (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
                isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
            ):
                skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return skip


def imports(path: Path) -> tuple[set[str], list[tuple[str, str]]]:
    """(first-party modules ``path`` imports, (module, name) of the private names it imports)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    skip = _type_checking_nodes(tree)
    found: set[str] = set()
    private: list[tuple[str, str]] = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name in MODULES}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in MODULES:
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                if sub in MODULES:
                    found.add(sub)
                else:
                    found.add(node.module)
                    if alias.name.startswith("_"):
                        private.append((node.module, alias.name))
    return found, private


def _graph() -> dict[str, set[str]]:
    return {name: imports(path)[0] - {name} for name, path in MODULES.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` as [a, b, ..., a], or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    stack: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                return stack[stack.index(w):] + [w]
            if w not in state:
                cycle = visit(w)
                if cycle:
                    return cycle
        stack.pop()
        state[v] = 2
        return None

    for v in sorted(graph):
        if v not in state:
            cycle = visit(v)
            if cycle:
                return cycle
    return None


def test_the_checker_sees_circles_and_lazy_imports(tmp_path):
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
    f = tmp_path / "m.py"
    f.write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from handover_env.envs.base_handover import HandoverEnvBase\n"
        "def g():\n    from handover_env.data.public import validate_record, _show\n"
    )
    found, private = imports(f)
    assert found == {"handover_env.data.public"}
    assert private == [("handover_env.data.public", "_show")]


def test_no_two_handover_env_modules_import_each_other():
    cycle = find_cycle(_graph())
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])


def test_no_private_name_is_imported_across_modules():
    shared = {
        name: private for name, path in MODULES.items() if (private := imports(path)[1])
    }
    assert not shared, f"private names imported from other modules: {shared}"


def test_long_modules_say_why():
    long = {}
    for name, path in MODULES.items():
        n = len(path.read_text(encoding="utf-8").splitlines())
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        if n > MAX_LINES and f"over {MAX_LINES} lines" not in doc:
            long[name] = n
    assert not long, f"modules over {MAX_LINES} lines whose docstring does not say why: {long}"


class _ReadOnlyEnv:
    """The env as a task sees it: every attribute readable, none writable."""

    def __init__(self, env) -> None:
        object.__setattr__(self, "_env", env)

    def __getattr__(self, name):
        return getattr(self._env, name)

    def __setattr__(self, name, value):
        raise AssertionError(f"a task wrote env.{name}")


class _Guarded:
    """A task whose methods get the read-only env."""

    def __init__(self, task) -> None:
        self._task = task

    def __getattr__(self, name):
        attr = getattr(self._task, name)
        if not callable(attr):
            return attr
        return lambda env, *args, **kwargs: attr(_ReadOnlyEnv(env), *args, **kwargs)


def _static_episode(guard: bool) -> tuple[list[float], dict, float, float]:
    env = gym.make("handover_env/StaticHandover-v0")
    u = env.unwrapped
    if guard:
        u.task = _Guarded(u.task)
    agent = StaticAgent()
    obs, _ = env.reset(seed=3, options={"receiver": "id"})
    agent.reset()
    enabled = [float(obs[u.layout.slices()["robot_enabled"][0]][0])]
    while True:
        obs, _, term, trunc, info = env.step(agent.act(obs))
        enabled.append(float(obs[u.layout.slices()["robot_enabled"][0]][0]))
        if term or trunc:
            break
    t_detect, t_enabled = u.t_detect, u.t_enabled
    env.close()
    return enabled, info, t_detect, t_enabled


def test_tasks_return_values_and_the_env_stores_them():
    enabled, info, t_detect, t_enabled = _static_episode(guard=True)
    # the env asked the task: the robot was held until the raised hand's detection + 2 s
    assert info["outcome"] == "success"
    assert not math.isnan(t_detect) and t_enabled == t_detect + 2.0
    assert enabled[0] == 0.0 and enabled[-1] == 1.0
    first = enabled.index(1.0)
    assert np.all(np.asarray(enabled[:first]) == 0.0) and np.all(np.asarray(enabled[first:]) == 1.0)
    assert abs(first / 30.0 - t_enabled) <= 1.0 / 30.0 + 1e-9
    # the same episode as with the task called directly
    plain = _static_episode(guard=False)
    assert plain[0] == enabled and plain[1] == info and plain[2:] == (t_detect, t_enabled)
