"""The shipped RL policy (``baselines/rl/policy``, issue 36): it loads through the safe loader,
records how it was trained, acts in the env, refuses what it trained on, ends in one named error
when tampered with, and ``evaluate.py benchmark --agent rl`` scores it with no training."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import gymnasium as gym
import pytest

import evaluate
import handover_env  # noqa: F401 - registers the envs
from baselines.checkpoint_io import CheckpointError
from baselines.rl.config import TRAIN_SEED_START
from baselines.rl.shipped import SHIPPED, load_shipped
from handover_env.config import HandoverParams
from handover_env.rollout import run_episode
from handover_eval import roster
from handover_eval.methods import MethodOptions


def test_it_is_small_and_records_its_configuration_commit_and_command():
    sizes = {p.name: p.stat().st_size for p in SHIPPED.iterdir()}
    assert set(sizes) == {"config.json", "model.safetensors"}
    assert sum(sizes.values()) < 1_000_000
    record = json.loads((SHIPPED / "config.json").read_text())
    c = record["config"]
    assert (c["form"], c["base"], c["use_sde"], c["action_tau"], c["last_actions"],
            c["privileged_critic"], c["steps"]) == ("residual", "cv", True, 0.1, 1, True,
                                                    1_000_000)
    v = record["versions"]
    assert re.fullmatch(r"[0-9a-f]{40}", v["commit"]) and v["dirty"] is False
    assert v["command"].startswith("python train.py rl ") and "--base cv" in v["command"]
    assert record["training"]["steps"] >= c["steps"]


def test_the_built_in_acts_deterministically_and_refuses_what_it_trained_on():
    agent = roster.build("rl", MethodOptions(), HandoverParams())
    assert roster.entry("rl").benchmark and roster.entry("rl").tracks == ("closedloop",)
    env = gym.make("handover_env/DynamicHandover-v0")
    try:
        runs = [run_episode(env, agent, seed=3, options={"receiver": "id"}) for _ in range(2)]
    finally:
        env.close()
    assert runs[0]["outcome"] == runs[1]["outcome"] != "running"
    assert runs[0]["time"] == runs[1]["time"]
    assert runs[0]["robot_jerk_rms"] == runs[1]["robot_jerk_rms"]
    trained = sorted(agent.trained_replays)
    assert len(trained) == len(agent.record["receivers"]["replay_ids"]) > 0
    with pytest.raises(ValueError, match="trained on the recording"):
        agent.check_receiver("replay", trained[0], 0)
    with pytest.raises(ValueError, match="RL training range"):
        agent.check_receiver("id", "walker", TRAIN_SEED_START)


@pytest.mark.parametrize("tamper", ["truncated weights", "config field", "link out"])
def test_a_tampered_copy_is_one_named_error(tmp_path, tamper):
    folder = tmp_path / "policy"
    shutil.copytree(SHIPPED, folder)
    if tamper == "truncated weights":
        raw = (folder / "model.safetensors").read_bytes()
        (folder / "model.safetensors").write_bytes(raw[:-8])
        name = "model.safetensors"
    elif tamper == "config field":
        record = json.loads((folder / "config.json").read_text())
        record["config"]["net_arch"] = [4096, 4096, 4096]
        (folder / "config.json").write_text(json.dumps(record))
        name = "config.json"
    else:
        outside = tmp_path / "elsewhere.safetensors"
        (folder / "model.safetensors").rename(outside)
        (folder / "model.safetensors").symlink_to(outside)
        name = "model.safetensors"
    with pytest.raises(CheckpointError, match=re.escape(name)) as err:
        load_shipped(folder=folder)
    assert "\n" not in str(err.value)


def test_a_missing_shipped_policy_is_named(tmp_path):
    with pytest.raises(CheckpointError, match="shipped RL policy is missing"):
        load_shipped(folder=tmp_path)


def test_the_benchmark_scores_it_with_no_training(tmp_path):
    out = tmp_path / "bench"
    assert evaluate.main(["benchmark", "--quick", "--no-progress", "--agent", "rl", "--tracks",
                          "closedloop", "--workers", "1", "--out", str(out)]) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["agent"]["name"] == "rl" and result["tracks"] == ["closedloop"]
    assert Path(out / "closedloop_episodes.csv").read_text().count("\nrl,") > 0
