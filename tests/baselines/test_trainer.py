"""The shared trainer of the torch baselines: one progress/log path, no LeRobot in BC-MLP, missing
extras."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("torch")

from baselines_toy import toy_dataset  # noqa: E402

from baselines.bc_mlp import BCMLPAgent, BCMLPConfig  # noqa: E402
from baselines.checkpoint_io import CheckpointError  # noqa: E402
from baselines.checkpoint_meta import SUMMARY_KEYS, read_checkpoint_json  # noqa: E402
from baselines.trainer import LOG_FILE  # noqa: E402


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)


def test_bc_mlp_does_not_import_lerobot():
    res = _run("import sys, baselines.bc_mlp, baselines.trainer; print('lerobot' in sys.modules)")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


@pytest.mark.parametrize(
    "module",
    ["baselines.bc_mlp", "baselines.act", "baselines.trainer", "baselines.checkpoint_meta"],
)
def test_a_baseline_without_its_extra_is_a_one_line_error_naming_it(module):
    res = _run(f"import sys; sys.modules['torch'] = None\nimport {module}")
    last = res.stderr.strip().splitlines()[-1]
    assert res.returncode != 0
    assert "MissingExtraError" in last and "[baselines]" in last and "pip install" in last


def test_training_writes_one_json_line_per_validation_and_a_tqdm_bar(tmp_path, capsys):
    data = toy_dataset(n=6, length=40, seed=3)
    out = tmp_path / "bc"
    agent = BCMLPAgent(BCMLPConfig(hidden=(16,), max_epochs=3, patience=50)).fit(
        data, out_dir=out, progress=True
    )
    lines = [json.loads(line) for line in (out / LOG_FILE).read_text().splitlines()]
    assert [r["epoch"] for r in lines] == [1, 2, 3]
    assert [r["val_loss"] for r in lines] == agent.train_log["val_loss"]
    assert lines[-1]["best_val"] == min(agent.train_log["val_loss"])
    assert "bc-mlp" in capsys.readouterr().err  # the tqdm bar
    # a resumed run keeps the earlier lines and appends its own
    BCMLPAgent(BCMLPConfig(hidden=(16,), max_epochs=5, patience=50)).fit(
        data, out_dir=out, resume=True
    )
    assert [json.loads(line)["epoch"] for line in (out / LOG_FILE).read_text().splitlines()] == [
        1,
        2,
        3,
        4,
        5,
    ]


def test_the_checkpoint_record_is_read_back_by_checkpoint_meta(tmp_path):
    out = tmp_path / "bc"
    agent = BCMLPAgent(BCMLPConfig(hidden=(8,), max_epochs=2, patience=50)).fit(
        toy_dataset(n=6, length=40, seed=4), out_dir=out
    )
    record = read_checkpoint_json(out, "config.json", "bc_mlp", 1, BCMLPConfig, "BC-MLP")
    assert record["type"] == "bc_mlp" and record["config"]["hidden"] == [8]
    assert set(record["training"]) <= set(SUMMARY_KEYS) and record["training"]["epoch"] == 2
    assert record["training"]["best_val"] == min(agent.train_log["val_loss"])
    with pytest.raises(CheckpointError, match="not 'act'"):
        read_checkpoint_json(out, "config.json", "act", 1, BCMLPConfig, "ACT")
