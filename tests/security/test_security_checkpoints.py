"""Issue 16 items 1, 10, 11: loading a checkpoint runs no code, and a tampered one is refused by
name."""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch  # noqa: E402

torch.set_num_threads(1)

from baselines_toy import toy_dataset  # noqa: E402
from safetensors.torch import load_file, save_file  # noqa: E402

from baselines.act import ACTAgent, ACTAgentConfig  # noqa: E402
from baselines.bc_mlp import BCMLPAgent, BCMLPConfig  # noqa: E402
from baselines.checkpoint_io import CheckpointError  # noqa: E402

ACT_TINY = {"policy": {"dim_model": 16, "n_heads": 2, "dim_feedforward": 32, "n_encoder_layers": 1,
                       "latent_dim": 4},
            "batch_size": 8, "steps": 2, "eval_every": 1,
            "use_giver_state": True}  # with observation.state, so its tampering is covered too
PRE, POST = "policy_preprocessor.json", "policy_postprocessor.json"
PRE_STATS = "policy_preprocessor_step_3_normalizer_processor.safetensors"
POST_STATS = "policy_postprocessor_step_0_unnormalizer_processor.safetensors"


@pytest.fixture(scope="module")
def data():
    return toy_dataset(n=6, length=40, seed=5)


#: The agent each checkpoint folder was saved from, to compare the loaded one's predictions with.
_SAVED_FROM: dict[Path, ACTAgent | BCMLPAgent] = {}


@pytest.fixture(scope="module")
def act_dir(data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("act") / "ckpt"
    agent = ACTAgent(ACTAgentConfig(**ACT_TINY)).fit(data, out_dir=out)
    agent.save(out)
    _SAVED_FROM[out] = agent
    return out


@pytest.fixture(scope="module")
def bc_dir(data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bc") / "ckpt"
    agent = BCMLPAgent(BCMLPConfig(hidden=(16,), max_epochs=2, use_giver_state=True)).fit(
        data, out_dir=out
    )
    agent.save(out)
    _SAVED_FROM[out] = agent
    return out


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


# ---------------------------------------------------------------------- item 1
def _edit_json(path: Path, edit: Callable[[dict], None]) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


POPEN = {"class": "subprocess.Popen", "config": {"args": ["sh", "-c", "id > MARKER"]}}


@pytest.mark.parametrize(
    "file, edit, message",
    [
        (
            PRE,
            lambda d: d["steps"].insert(0, POPEN),
            r"policy_preprocessor\.json: step 0 names the class 'subprocess\.Popen'",
        ),
        (
            POST,
            lambda d: d["steps"].insert(1, POPEN),
            r"policy_postprocessor\.json: step 1 names the class 'subprocess\.Popen'",
        ),
        (
            PRE,
            lambda d: d["steps"][0].update({"class": "os.system"}),
            r"step 0 names the class 'os\.system'",
        ),
        (
            PRE,
            lambda d: d["steps"][1].update({"registry_name": "tokenizer_processor"}),
            r"step 1 names the processor 'tokenizer_processor', which is not one of the steps",
        ),
        (
            PRE,
            lambda d: d["steps"][0]["config"].update(
                {"rename_map": {"action": "observation.state"}}
            ),
            r"step 0 \(rename_observations_processor\) has the config",
        ),
        (
            PRE,
            lambda d: d["steps"][3].update({"state_file": "../../etc/passwd"}),
            r"step 3 \(normalizer_processor\) must have state_file",
        ),
        (
            POST,
            lambda d: d["steps"].reverse(),
            r"step 0 is 'device_processor'; the steps must be exactly",
        ),
        (
            PRE,
            lambda d: d["steps"].append(d["steps"][0]),
            r"step 4 is 'rename_observations_processor'; the steps must",
        ),
        (PRE, lambda d: d["steps"].pop(), r"policy_preprocessor\.json: 3 steps, expected"),
    ],
    ids=[
        "popen-pre",
        "popen-post",
        "class-beside-registry",
        "other-registry-step",
        "changed-config",
        "state-file-path",
        "reordered",
        "extra-step",
        "missing-step",
    ],
)
def test_processor_json_is_allow_listed_before_lerobot_sees_it(
    act_dir, tmp_path, monkeypatch, file, edit, message
):
    folder = _copy(act_dir, tmp_path / "ckpt")
    _edit_json(folder / file, edit)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(CheckpointError, match=message):
        ACTAgent.load(folder)
    assert not (tmp_path / "MARKER").exists()


def test_evaluate_does_not_run_a_tampered_cached_checkpoint(data, tmp_path, monkeypatch):
    """evaluate.py reuses checkpoints from <out>/checkpoints: a tampered one is retrained, not
    run."""
    from handover_eval.methods import (
        MethodOptions,
        build_agent,
        checkpoint_slot,
        fit_agent,
    )

    options = MethodOptions(seed=0, quick=True, act_steps=2, workers=1)
    _, reused = fit_agent("act", build_agent("act", options), data, tmp_path / "cache")
    assert not reused
    folder, _ = checkpoint_slot("act", build_agent("act", options), data, tmp_path / "cache")
    _edit_json(folder / PRE, lambda d: d["steps"].insert(0, POPEN))
    monkeypatch.chdir(tmp_path)
    _, reused = fit_agent("act", build_agent("act", options), data, tmp_path / "cache")
    assert not reused and not (tmp_path / "MARKER").exists()
    assert ACTAgent.load(folder).fitted  # the retrained checkpoint is clean again


# ---------------------------------------------------------------------- items 10 and 11
def _tensors(path: Path, edit: Callable[[dict], None]) -> None:
    tensors = load_file(path)
    edit(tensors)
    save_file(tensors, path)


def _first_float(t: dict) -> str:
    return next(k for k, v in sorted(t.items()) if v.is_floating_point() and v.numel() > 1)


def _set(key_of: Callable[[dict], str], value: Callable[[torch.Tensor], torch.Tensor]):
    def edit(t: dict) -> None:
        key = key_of(t)
        t[key] = value(t[key])
    return edit


def _nan(t: torch.Tensor) -> torch.Tensor:
    t = t.clone()
    t.view(-1)[0] = float("nan")
    return t


COMMON = {  # tamperings of files both kinds share: name -> (file, how)
    "weights-truncated": ("model.safetensors", lambda p: p.write_bytes(p.read_bytes()[:100])),
    "weights-garbage": ("model.safetensors", lambda p: p.write_bytes(b"\x00" * 64)),
    "weights-missing": ("model.safetensors", lambda p: p.unlink()),
    "weights-nan": ("model.safetensors", lambda p: _tensors(p, _set(_first_float, _nan))),
    "weights-int64": (
        "model.safetensors",
        lambda p: _tensors(p, _set(_first_float, lambda t: t.long())),
    ),
    "weights-shape": (
        "model.safetensors",
        lambda p: _tensors(p, _set(_first_float, lambda t: t[:1])),
    ),
    "weights-missing-key": (
        "model.safetensors",
        lambda p: _tensors(p, lambda t: t.pop(_first_float(t))),
    ),
    "weights-extra-key": (
        "model.safetensors",
        lambda p: _tensors(p, lambda t: t.update(extra=torch.zeros(2))),
    ),
}

BC_TAMPER = {
    **COMMON,
    "config-garbage": ("config.json", lambda p: p.write_text("{not json")),
    "config-list": ("config.json", lambda p: p.write_text("[]")),
    "config-bool-string": (
        "config.json",
        lambda p: _edit_json(p, lambda d: d["config"].update(use_giver_state="no")),
    ),
    "config-missing-key": ("config.json", lambda p: _edit_json(p, lambda d: d["config"].pop("lr"))),
    "config-float-int": (
        "config.json",
        lambda p: _edit_json(p, lambda d: d["config"].update(history=2.5)),
    ),
    "config-features": (
        "config.json",
        lambda p: _edit_json(p, lambda d: d["features"].update(history=3)),
    ),
    "config-type": ("config.json", lambda p: _edit_json(p, lambda d: d.pop("type"))),
    "zero-std": (
        "model.safetensors",
        lambda p: _tensors(p, _set(lambda t: "out_std", torch.zeros_like)),
    ),
}

ACT_TAMPER = {
    **COMMON,
    "handover-garbage": ("handover_act.json", lambda p: p.write_text("\x00\x01")),
    "handover-bool-string": (
        "handover_act.json",
        lambda p: _edit_json(p, lambda d: d["config"].update(use_vae="no")),
    ),
    "handover-missing-key": (
        "handover_act.json",
        lambda p: _edit_json(p, lambda d: d["config"].pop("batch_size")),
    ),
    "handover-policy-owned": (
        "handover_act.json",
        lambda p: _edit_json(p, lambda d: d["config"]["policy"].update(chunk_size=5)),
    ),
    "handover-policy-type": (
        "handover_act.json",
        lambda p: _edit_json(p, lambda d: d["config"]["policy"].update(dim_model="16")),
    ),
    "handover-policy-list": (
        "handover_act.json",
        lambda p: _edit_json(p, lambda d: d["config"].update(policy=[1])),
    ),
    "handover-giver-state": (
        "handover_act.json",
        lambda p: _edit_json(p, lambda d: d["config"].update(use_giver_state=False)),
    ),
    "config-json-garbage": ("config.json", lambda p: p.write_text("{")),
    "config-json-chunk": (
        "config.json",
        lambda p: _edit_json(p, lambda d: d.update(chunk_size=10)),
    ),
    "config-json-state": (
        "config.json",
        lambda p: _edit_json(p, lambda d: d["input_features"].pop("observation.state")),
    ),
    "processor-garbage": (PRE, lambda p: p.write_text("[1, 2")),
    "stats-zero-std": (
        PRE_STATS,
        lambda p: _tensors(p, _set(lambda t: "action.std", torch.zeros_like)),
    ),
    "stats-nan": (POST_STATS, lambda p: _tensors(p, _set(lambda t: "action.mean", _nan))),
    "stats-truncated": (PRE_STATS, lambda p: p.write_bytes(p.read_bytes()[:40])),
    "stats-missing": (POST_STATS, lambda p: p.unlink()),
    "stats-unknown-key": (
        PRE_STATS,
        lambda p: _tensors(p, lambda t: t.update({"action.evil": torch.ones(3)})),
    ),
}


@pytest.mark.parametrize("name", sorted(BC_TAMPER))
def test_tampered_bc_mlp_checkpoint_is_a_checkpoint_error_naming_it(bc_dir, tmp_path, name):
    folder = _copy(bc_dir, tmp_path / "ckpt")
    file, tamper = BC_TAMPER[name]
    tamper(folder / file)
    with pytest.raises(CheckpointError, match=re.escape(str(folder))) as info:
        BCMLPAgent.load(folder)
    assert str(folder) in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("name", sorted(ACT_TAMPER))
def test_tampered_act_checkpoint_is_a_checkpoint_error_naming_it(act_dir, tmp_path, name):
    folder = _copy(act_dir, tmp_path / "ckpt")
    file, tamper = ACT_TAMPER[name]
    tamper(folder / file)
    with pytest.raises(CheckpointError, match=re.escape(str(folder))) as info:
        ACTAgent.load(folder)
    assert str(folder) in str(info.value) and "\n" not in str(info.value)


def test_use_giver_state_is_cross_checked_with_lerobots_config(act_dir, tmp_path):
    folder = _copy(act_dir, tmp_path / "ckpt")
    _edit_json(folder / "handover_act.json", lambda d: d["config"].update(use_giver_state=False))
    with pytest.raises(
        CheckpointError,
        match=r"config\.json disagrees with handover_act\.json in \['input_features'\]",
    ):
        ACTAgent.load(folder)


def test_untampered_checkpoints_still_round_trip(act_dir, bc_dir, data):
    ep = data[0]
    for folder, agent in ((act_dir, ACTAgent.load(act_dir)), (bc_dir, BCMLPAgent.load(bc_dir))):
        pred = agent.predict(ep.receiver_xy[:12], ep.giver_xyz[11])
        assert pred.shape == (30, 3) and torch.isfinite(torch.as_tensor(pred)).all()
        saved = _SAVED_FROM[folder]
        np.testing.assert_array_equal(pred, saved.predict(ep.receiver_xy[:12], ep.giver_xyz[11]))
        np.testing.assert_array_equal(  # a later moment too: the same weights, not one answer
            agent.predict(ep.receiver_xy[:30], ep.giver_xyz[29]),
            saved.predict(ep.receiver_xy[:30], ep.giver_xyz[29]),
        )
