"""ACT fold pre-training: one shared export, fold models in worker processes, reused by
fit_agent."""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

torch.set_num_threads(1)  # 2 threads on a shared 2-core box run ~10x slower

from baselines_toy import toy_dataset  # noqa: E402

from handover_eval.act_folds import (  # noqa: E402
    EXPORT_PREFIX,
    ensure_export,
    episode_indices,
    pretrain_act,
)
from handover_eval.methods import (  # noqa: E402
    ACT_EVAL_STEPS,
    COMPLETE,
    MethodOptions,
    build_agent,
    checkpoint_slot,
    default_workers,
    fit_agent,
)

OPTIONS = MethodOptions(quick=True, act_steps=16)


@pytest.fixture(scope="module")
def data():
    return toy_dataset(n=18, length=45, seed=4)


@pytest.fixture(scope="module")
def folds(data):
    return data.stratified_kfold(3, seed=0)


def _predictions(agent, data) -> np.ndarray:
    ep = data[0]
    return agent.predict_episode(ep, np.arange(5, ep.length))


def test_export_is_made_once_and_reused(data, tmp_path):
    root, reused = ensure_export(data, tmp_path, history=10, horizon=30)
    assert (
        not reused
        and root.name.startswith(EXPORT_PREFIX)
        and (root / "meta" / "handover.json").is_file()
    )
    stamp = (root / "meta" / "info.json").stat().st_mtime_ns
    again, reused = ensure_export(data, tmp_path, history=10, horizon=30)
    assert reused and again == root and (root / "meta" / "info.json").stat().st_mtime_ns == stamp
    # Another W, or another dataset, is another export.
    other, _ = ensure_export(data, tmp_path, history=6, horizon=30)
    assert other != root
    assert ensure_export(data.subset(range(10)), tmp_path, history=10, horizon=30)[0] not in (
        root,
        other,
    )
    # An export whose sidecar disagrees with the dataset (e.g. damaged) is rebuilt, not trusted.
    (root / "meta" / "handover.json").unlink()
    rebuilt, reused = ensure_export(data, tmp_path, history=10, horizon=30)
    assert not reused and rebuilt == root and (root / "meta" / "handover.json").is_file()
    assert not list(tmp_path.glob("*.partial-*"))


def test_episode_indices_of_subsets(data):
    idx = np.array([7, 1, 4, 10])
    np.testing.assert_array_equal(episode_indices(data, data.subset(idx)), idx)
    part = data.subset(np.arange(8)).subsample(0.5, seed=2)
    got = episode_indices(data, part)
    assert [data[i].source_id for i in got] == [ep.source_id for ep in part]
    with pytest.raises(ValueError, match="not in the dataset"):
        episode_indices(data.subset(range(4)), data.subset([5]))


def test_parallel_pretraining_equals_fit_agent_and_is_reused(data, folds, tmp_path):
    """2 spawned workers on one export give bitwise the models fit_agent trains from per-fold
    exports (two of the three folds: one job per worker)."""
    cache = tmp_path / "parallel"
    sets = [train for train, _ in folds[:2]]
    runs = pretrain_act(data, sets, OPTIONS, cache, workers=2, progress=False)
    assert len(runs) == 2 and all(r.trained and r.fit_seconds > 0 for r in runs)
    assert len(list(cache.glob(f"{EXPORT_PREFIX}*"))) == 1  # one export for all folds
    for f, run in enumerate(runs):
        train = data.subset(sets[f])
        folder, key_src = checkpoint_slot("act", build_agent("act", OPTIONS), train, cache)
        assert run.folder == folder and (folder / COMPLETE).read_text() == key_src
        loaded, reused = fit_agent("act", build_agent("act", OPTIONS), train, cache)
        assert reused
        assert loaded.train_log["step"] == 16 and loaded.train_log["best_step"] == run.best_step
        # The classic path: fit_agent exports this fold's training set alone and trains in-process.
        classic, reused = fit_agent(
            "act", build_agent("act", OPTIONS), train, tmp_path / f"classic{f}"
        )
        assert not reused
        np.testing.assert_array_equal(_predictions(loaded, data), _predictions(classic, data))
    # A second call finds every checkpoint complete and trains nothing (no export needed either).
    again = pretrain_act(data, sets, OPTIONS, cache, workers=2, progress=False)
    assert [r.folder for r in again] == [r.folder for r in runs] and not any(
        r.trained for r in again
    )
    # reuse=False retrains (here in this process: workers=1), to the same model.
    before = _predictions(_load_act(runs[0].folder), data)
    lines: list[str] = []
    fresh = pretrain_act(
        data, sets[:1], OPTIONS, cache, reuse=False, workers=1, progress=False, log=lines.append
    )
    assert fresh[0].trained and fresh[0].folder == runs[0].folder
    assert "1 process" in lines[0] and "best val L1" in lines[-1]
    np.testing.assert_array_equal(_predictions(_load_act(runs[0].folder), data), before)


def _load_act(folder: Path):
    from baselines.act import ACTAgent

    return ACTAgent.load(folder)


def test_identical_training_sets_share_one_model(data, folds, tmp_path):
    train = folds[0][0]
    runs = pretrain_act(
        data, [train, train.copy()], OPTIONS, tmp_path, workers=2, labels=["a", "b"], progress=False
    )
    assert runs[0].folder == runs[1].folder and runs[0].trained and runs[1].trained
    assert len(list(tmp_path.glob("act-*"))) == 2  # one checkpoint + the export


def test_workers_option_and_eval_budget():
    assert MethodOptions().workers == default_workers() == max(1, min(2, os.cpu_count() or 1))
    with pytest.raises(ValueError, match="workers"):
        MethodOptions(workers=0)
    cfg = build_agent("act", MethodOptions()).config
    assert (cfg.steps, cfg.eval_every) == (ACT_EVAL_STEPS, ACT_EVAL_STEPS // 8)
    assert not cfg.use_giver_state
    quick = build_agent("act", MethodOptions(quick=True)).config
    assert quick.steps == 40 and quick.model()["dim_model"] == 32
    assert build_agent("act", MethodOptions(act_steps=800)).config.eval_every == 100


def test_failing_workers_are_named(tmp_path):
    from handover_eval.act_folds import ACTJob, run_act_jobs
    from handover_eval.backend import JobError

    config = asdict(build_agent("act", OPTIONS).config)
    jobs = [
        ACTJob(
            f"job {i}",
            config,
            (0, 1, 2),
            str(tmp_path / f"ck{i}"),
            "{}",
            str(tmp_path / "no-export"),
        )
        for i in range(3)
    ]
    with pytest.raises(JobError, match="not a handover LeRobot export") as err:
        run_act_jobs(jobs, workers=2, progress=False, log=None)
    assert sorted(err.value.failed) == ["job 0", "job 1", "job 2"]  # each retried once, then named
    assert isinstance(err.value.__cause__, FileNotFoundError)
    assert not any((tmp_path / f"ck{i}" / COMPLETE).exists() for i in range(3))


def test_sample_efficiency_pretrains_every_fold_and_ratio(tmp_path):
    from handover_env.person.synthetic import generate_synthetic
    from handover_eval.openloop.experiments import run_sample_efficiency
    from handover_eval.openloop.protocol import OpenLoopProtocol

    data = generate_synthetic(n=16, ood_fraction=0.25, seed=5)
    protocol = OpenLoopProtocol(stride=5)
    rows = run_sample_efficiency(
        data, ["act"], [0.5, 1.0], 2, 0, OPTIONS, protocol, tmp_path, progress=False, workers=2
    ).rows
    assert [(r["method"], r["ratio"]) for r in rows] == [("act", 0.5), ("act", 1.0)]
    assert all(np.isfinite(r["all_rms_3d_mm"]) for r in rows)
    ckpt = tmp_path / "checkpoints"
    models = [p for p in ckpt.glob("act-*") if not p.name.startswith(EXPORT_PREFIX)]
    assert len(models) == 4 and all((p / COMPLETE).is_file() for p in models)  # 2 folds x 2 ratios
    assert len(list(ckpt.glob(f"{EXPORT_PREFIX}*"))) == 1
