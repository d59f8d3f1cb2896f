"""``train.py rl``: the training data, one seed's training, and several seeds in parallel.

**Receivers.** Scripted ID and OOD walkers with seeds from the training range
(:mod:`baselines.rl.config`: every one >= ``TRAIN_SEED_START``, above every closed-loop
evaluation seed) and replays of the dataset episodes of the training folds of Table I's
stratified split (:func:`baselines.rl.config.training_folds`: folds ``0 .. k//2 - 1``, the
complement of :func:`handover_eval.receivers.held_out_folds`, checked here). The
replays are the dataset's :class:`~handover_env.data.dataset.Episode` objects (the body walks
the recorded pelvis track). The SPGP base (``--base ours``) is fitted on the same episodes.

**Seeds.** One seed trains in this process (its envs in their own processes); several are
independent jobs of :func:`handover_eval.backend.map_jobs` (processes or Ray), each writing its
own checkpoint folder.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from baselines.rl.config import RLConfig, training_folds
from baselines.rl.train import TrainingData, train_policy
from handover_env.data.dataset import HandoverDataset
from handover_eval.receivers import fold_of, held_out_folds

#: ``--quick``: a few hundred steps of a tiny network on walkers only (tests, make test).


def training_data(dataset: HandoverDataset | None, config: RLConfig) -> TrainingData:
    """The replays (and the SPGP base's fit) of the training folds of ``dataset`` (module
    docstring); no replays when ``dataset`` is None or ``config.p_replay`` is 0 (a base ``ours``
    still needs the dataset)."""
    needs_base = (config.form == "residual" and config.base == "ours") or (
        config.warm_start == "ours")
    if dataset is None or (config.p_replay == 0 and not needs_base):
        return TrainingData()
    folds = training_folds(config.folds)
    overlap = set(folds) & set(held_out_folds(config.folds))
    if overlap:  # never: the two are complements by construction (tests/baselines/test_rl.py)
        raise RuntimeError(f"training folds {sorted(overlap)} are held out for evaluation")
    ids = fold_of(dataset, config.folds, config.split_seed)
    idx = np.flatnonzero(np.isin(ids, folds))
    if idx.size == 0:
        raise ValueError(f"no episodes in the training folds {list(folds)} of {dataset.name}")
    subset = dataset.subset(idx)
    episodes = [subset[i] for i in range(len(subset))] if config.p_replay > 0 else []
    return TrainingData(
        replays=episodes,
        replay_ids=[ep.source_id for ep in episodes],
        folds=folds,
        dataset=dataset.name,
        base_fit=subset if needs_base else None,
    )


@dataclass(frozen=True)
class SeedJob:
    """One seed's training run (a :func:`handover_eval.backend.map_jobs` job)."""

    config: RLConfig
    out: Path
    resume: bool


def train_seed(data: TrainingData, job: SeedJob) -> dict:
    """Train ``job``'s seed into its folder (module-level: runs in a backend worker); the
    state, with the curve CSV/PNG written after every checkpoint."""
    from handover_eval.rl.output import write_curve

    return train_policy(job.config, job.out, data, resume=job.resume, progress=False,
                        on_checkpoint=lambda state: write_curve(job.out, state, job.config))


def seed_folders(out: Path, seeds: list[int]) -> list[Path]:
    """The checkpoint folder of each seed: ``out`` itself for one seed, else ``out/seed-S``."""
    return [out] if len(seeds) == 1 else [out / f"seed-{s}" for s in seeds]


def run_training(config: RLConfig, seeds: list[int], out: Path, data: TrainingData,
                 resume: bool, workers: int, progress: bool, log=print) -> list[dict]:
    """Train every seed of ``seeds`` (one in this process, several as backend jobs); their final
    states, in seed order."""
    from handover_eval.rl.output import write_curve

    folders = seed_folders(out, seeds)
    jobs = [SeedJob(replace(config, seed=s), f, resume) for s, f in zip(seeds, folders,
                                                                        strict=True)]
    if len(jobs) == 1:
        job = jobs[0]
        return [train_policy(job.config, job.out, data, resume=resume, progress=progress, log=log,
                             on_checkpoint=lambda state: write_curve(job.out, state, job.config))]
    from handover_eval.backend import map_jobs

    return map_jobs(train_seed, data, jobs, workers=workers, progress=progress, desc="rl seeds",
                    label=lambda j: f"seed {j.config.seed}")
