"""Issue 16 item 20: ACT training is bit-reproducible under its seed, whatever process trains it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch  # noqa: E402
from baselines_toy import toy_dataset  # noqa: E402
from safetensors.torch import load_file  # noqa: E402

REPO = Path(__file__).resolve().parents[2]

# One training in a fresh process. The processes differ in everything a seed must not depend on:
# the torch thread count the caller set, what the global RNGs already produced, the hash seed.
TRAIN = r"""
import random, sys
import numpy as np, torch
torch.set_num_threads(int(sys.argv[3]))
torch.rand(int(sys.argv[4])); np.random.rand(int(sys.argv[4])); random.random()
from baselines.act import ACTAgent, ACTAgentConfig
config = ACTAgentConfig(policy=dict(dim_model=32, n_heads=2, dim_feedforward=64, n_encoder_layers=1,
                                   latent_dim=4,
                                   optimizer_lr=1e-3), batch_size=16, steps=6, eval_every=3, seed=7)
agent = ACTAgent(config).fit_lerobot(sys.argv[1], out_dir=sys.argv[2])
assert torch.get_num_threads() == int(sys.argv[3])  # the caller's setting is restored
"""


def _train(
    export: Path, out: Path, threads: int, consumed: int, hash_seed: str
) -> dict[str, torch.Tensor]:
    env = {
        **os.environ,
        "PYTHONPATH": str(REPO),
        "PYTHONHASHSEED": hash_seed,
        "OMP_NUM_THREADS": str(threads),
    }
    result = subprocess.run(
        [sys.executable, "-c", TRAIN, str(export), str(out), str(threads), str(consumed)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return load_file(out / "training_state" / "last.safetensors")


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs 2 cores to run 2 torch threads")
def test_two_processes_train_identical_weights(tmp_path: Path) -> None:
    from handover_env.data.lerobot_export import export_lerobot

    export = export_lerobot(toy_dataset(n=8, length=45, seed=2), tmp_path / "export")
    a = _train(export, tmp_path / "a", threads=1, consumed=0, hash_seed="0")
    b = _train(export, tmp_path / "b", threads=2, consumed=1000, hash_seed="1")
    assert a.keys() == b.keys() and len(a) > 10
    differing = [k for k in a if not torch.equal(a[k], b[k])]
    assert not differing, f"{len(differing)} of {len(a)} tensors differ, e.g. {differing[:3]}"
    best_a, best_b = (
        load_file(tmp_path / "a" / "model.safetensors"),
        load_file(tmp_path / "b" / "model.safetensors"),
    )
    assert all(torch.equal(best_a[k], best_b[k]) for k in best_a)
