"""train.py: --help documents every flag; smoke trainings of both baselines round-trip
checkpoints."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from baselines_toy import toy_dataset

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1"}
sys.path.insert(0, str(ROOT))

from handover_eval.cli import train  # noqa: E402


@pytest.mark.parametrize("method", ["bc-mlp", "act"])
def test_help_documents_every_flag(method):
    sub = train.build_parser()._subparsers._group_actions[0].choices[method]
    for action in sub._actions:
        if action.option_strings and action.dest != "help":
            assert action.help, f"{method} {action.option_strings} has no help text"
    out = subprocess.run(
        [sys.executable, str(ROOT / "train.py"), method, "--help"],
        cwd=ROOT,
        env=ENV,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0
    for flag in (
        "--data",
        "--out",
        "--smoke",
        "--resume",
        "--seed",
        "--batch-size",
        "--lr",
        "--device",
    ):
        assert flag in out.stdout


def test_smoke_trains_both_baselines_and_round_trips(tmp_path):
    from baselines.act import ACTAgent
    from baselines.bc_mlp import BCMLPAgent

    data = toy_dataset(n=12, length=45, seed=3)
    data_path = data.save(tmp_path / "toy.npz")
    t0 = time.perf_counter()
    for method in ("bc-mlp", "act"):
        train.main([method, "--smoke", "--data", str(data_path), "--out", str(tmp_path / method),
                    "--test-fold", "0", "--folds", "2", "--no-progress"])
        summary = json.loads((tmp_path / method / "train_summary.json").read_text())
        assert (
            np.isfinite(summary["final_val_loss"])
            and summary["test_rms_mm"]["id"]["n_episodes"] > 0
        )
    ep = data[0]
    for agent in (BCMLPAgent.load(tmp_path / "bc-mlp"), ACTAgent.load(tmp_path / "act")):
        pred = agent.predict(ep.receiver_xy[:12], ep.giver_xyz[11])
        assert pred.shape == (30, 3) and np.all(np.isfinite(pred))
    # resuming a finished run continues from its saved state (nothing left to do) and still reports
    train.main(["bc-mlp", "--smoke", "--data", str(data_path), "--out", str(tmp_path / "bc-mlp"),
                "--test-fold", "0", "--folds", "2", "--resume", "--no-progress"])
    assert time.perf_counter() - t0 < 120


def test_bad_inputs_fail_clearly(tmp_path, capsys):
    """Bad input ends with exit status 2 and one line naming the problem (no traceback)."""
    def run(argv: list[str]) -> str:
        assert train.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("train.py: error: ") and "\n" not in err, err
        return err

    assert "no dataset" in run(
        ["bc-mlp", "--smoke", "--data", str(tmp_path / "nope.npz"), "--out", str(tmp_path / "o")]
    )
    short = toy_dataset(n=6, length=20, seed=0).save(tmp_path / "short.npz")
    assert "horizon H=60 frames is longer than" in run(
        ["act", "--smoke", "--data", str(short), "--out", str(tmp_path / "o"), "--horizon", "60"])
    good = toy_dataset(n=6, length=45, seed=0).save(tmp_path / "good.npz")
    assert "cannot resume" in run(
        ["bc-mlp", "--smoke", "--data", str(good), "--out", str(tmp_path / "o2"), "--resume"]
    )
