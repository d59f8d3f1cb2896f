"""One default and no hidden side effects across the entry points, the agents and the benches."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from agents.nonparametric import NonparametricConfig
from baselines.iaal import IAALAgent

ROOT = Path(__file__).resolve().parents[2]


def test_iaal_config_reports_only_what_the_model_uses():
    cfg = IAALAgent(NonparametricConfig(inducing_ratio=0.4)).config
    assert cfg.exact and cfg.inducing_ratio == 1.0  # an exact GP: every sample, whatever was asked


def test_the_giver_state_default_is_receiver_only_everywhere():
    pytest.importorskip("torch")
    from baselines.act import ACTAgentConfig
    from baselines.bc_mlp import BCMLPConfig
    from handover_eval.cli import evaluate as evaluate_cli
    from handover_eval.cli import train as train_cli
    from handover_eval.methods import MethodOptions, build_agent

    assert BCMLPConfig().use_giver_state is False and ACTAgentConfig().use_giver_state is False
    assert MethodOptions().giver_state is False
    assert build_agent("bc_mlp", MethodOptions()).config.use_giver_state is False
    train = train_cli.build_parser()
    for cmd in ("bc-mlp", "act"):
        assert train.parse_args([cmd, "--out", "x"]).giver_state is False
        assert train.parse_args([cmd, "--out", "x", "--giver-state"]).giver_state is True
    assert evaluate_cli.build_parser().parse_args(["table1"]).giver_state is False


def test_importing_the_library_leaves_the_hugging_face_variables_alone():
    modules = [
        "handover_env",
        "handover_env.data.lerobot_export",
        "handover_eval.cli.data",
        "agents.nonparametric",
        "handover_eval.methods",
        "handover_eval.act_folds",
        "handover_eval.cli.evaluate",
        "handover_eval.cli.train",
        "handover_eval.closedloop.run",
    ]
    try:
        import torch  # noqa: F401

        modules += ["baselines.act", "baselines.bc_mlp"]
    except ImportError:
        pass
    code = (f"import importlib, os\nfor m in {modules!r}: importlib.import_module(m)\n"
            "print(sorted(k for k in os.environ if k.startswith('HF_') and k.endswith('OFFLINE')))")
    env = {
        k: v for k, v in os.environ.items() if not (k.startswith("HF_") and k.endswith("OFFLINE"))
    }
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300, cwd=ROOT
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


def test_the_cli_entry_points_set_offline_mode():
    env = {
        k: v for k, v in os.environ.items() if not (k.startswith("HF_") and k.endswith("OFFLINE"))
    }
    code = ("import os, sys\nfrom handover_eval.cli.evaluate import main\n"
            "try:\n    main(['table1', '--methods', 'nope'])\nexcept SystemExit:\n    pass\n"
            "print(os.environ.get('HF_HUB_OFFLINE'), os.environ.get('HF_DATASETS_OFFLINE'))")
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300, cwd=ROOT
    )
    assert res.stdout.strip().splitlines()[-1] == "1 1", res.stderr


@pytest.mark.parametrize("bench", sorted(p.name for p in (ROOT / "bench").glob("*.py")))
def test_a_bench_that_loads_a_dataset_says_which(bench):
    text = (ROOT / "bench" / bench).read_text(encoding="utf-8")
    if "load_any(" in text:
        assert 'f"data: ' in text, f"bench/{bench} loads a dataset without saying which"
