"""The packages form one-way layers: no module imports a layer above its own.

| layer | packages | may import |
| --- | --- | --- |
| 0, bottom | ``handover_env`` (simulator, data, feature encoders) | itself |
| 1, middle | ``agents``, ``baselines`` | layers 0-1 |
| 2, top | ``handover_eval`` (evaluation, CLIs, demo), ``train.py``, ``evaluate.py`` | layers 0-2 |

Every import counts, at module level or inside a function (a lazy import is still a dependency),
read from the source with :mod:`ast`, so nothing is executed.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = {"handover_env": 0, "agents": 1, "baselines": 1, "handover_eval": 2}
SCRIPTS = {"train.py": 2, "evaluate.py": 2}


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
