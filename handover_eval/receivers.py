"""The receivers of the closed-loop evaluation: scripted walkers and replayed recordings.

Every agent meets the same receivers, so that each can be paired with the reactive agent:

* **Scripted walkers** (sets ``id`` and ``ood``): ``reset(seed=s, options={"receiver": kind})``
  with seeds ``0 .. N-1`` (ID) and ``10000 .. 10000+N-1`` (OOD), as the benches use.
* **Replays** (set ``replay``): the episodes of chosen folds of Table I's stratified split
  (default: the held-out half, folds ``k//2 .. k-1``, i.e. 5-9 of 10, which the receiver was not
  calibrated on). From a public-dataset folder each is a
  :class:`~handover_env.person.recording.Recording` (the whole BODY_34 skeleton drives the body);
  from a ``.npz`` or the synthetic generator it is an :class:`~handover_env.data.dataset.Episode`
  (the body walks the recorded pelvis track with a scripted gait). The reset seed of a replay is
  its dataset index.

With ``--replay-data`` (:func:`other_replays`) the replays are every episode of another dataset
instead: none of it is in ``--data``, the models fit on all of ``--data``
(:data:`FIT_ALL`), and a replay's dataset index is its place after ``--data``'s episodes in the
one dataset the workers receive (:func:`handover_eval.methods.with_test_data`).

For recordings, :func:`recorded_transfer` gives when and where the recorded receiver took the
object (``handover_env.data.detect.detect_transfer`` on the smoothed skeleton and
object), the reference that the simulated transfer is compared with (Δt, Δx).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handover_env.data.dataset import HandoverDataset, stratified_fold_ids

SETS: tuple[str, ...] = ("id", "ood", "replay")
#: The model "fold" of ``--replay-data`` runs: fitted on every episode of ``--data``.
FIT_ALL = -1
FIRST_SEED = {"id": 0, "ood": 10_000}
RATE_HZ = 30.0


@dataclass(frozen=True)
class ReceiverSpec:
    """One receiver every agent meets.

    Attributes:
        set: "id", "ood" (scripted walkers) or "replay".
        key: unique within the set: ``id-0003`` or the recording's source id.
        seed: the env reset seed.
        fold: a replay's fold in Table I's split (None for walkers).
        index: a replay's index in the dataset (None for walkers).
        path: a replay's recording file (None: replay the dataset episode).
        is_ood: OOD walker or OOD recording.
        recorded_transfer_time: s from the start of the recording to the recorded grasp (NaN
            if undetected or no skeleton).
        recorded_pelvis_x: the recorded receiver's smoothed pelvis x at that frame, m (NaN too).
    """

    set: str
    key: str
    seed: int
    fold: int | None = None
    index: int | None = None
    path: str | None = None
    is_ood: bool = False
    recorded_transfer_time: float = math.nan
    recorded_pelvis_x: float = math.nan


def walkers(n: int, sets: tuple[str, ...] = ("id", "ood")) -> list[ReceiverSpec]:
    """``n`` seeded scripted walkers of each of ``sets`` (``id``/``ood``)."""
    if n < 0:
        raise ValueError(f"--walkers must be >= 0, got {n}")
    out = []
    for kind in sets:
        if kind not in FIRST_SEED:
            raise ValueError(f"walker set must be 'id' or 'ood', got {kind!r}")
        out += [
            ReceiverSpec(kind, f"{kind}-{i:04d}", FIRST_SEED[kind] + i, is_ood=kind == "ood")
            for i in range(n)
        ]
    return out


def held_out_folds(folds: int) -> tuple[int, ...]:
    """The held-out half of a k-fold split: folds ``k//2 .. k-1`` (5-9 of 10)."""
    return tuple(range(folds // 2, folds))


def fold_of(dataset: HandoverDataset, folds: int, seed: int) -> np.ndarray:
    """Table I's fold of every episode (a clear ValueError when the split is impossible)."""
    if folds < 2:
        raise ValueError(f"--folds must be >= 2, got {folds}")
    return stratified_fold_ids(dataset.ood_mask, folds, seed)


def recording_paths(data: str | None, dataset: HandoverDataset) -> dict[str, str]:
    """Source id -> recording file, for a public-dataset folder (empty for a .npz or synthetic)."""
    if data is None or not Path(data).is_dir():
        return {}
    from handover_env.data.public import list_public_files

    paths = {p.stem: str(p) for p in list_public_files(data)}
    return {ep.source_id: paths[ep.source_id] for ep in dataset if ep.source_id in paths}


def pick_evenly(indices: np.ndarray, k: int | None) -> np.ndarray:
    """``k`` of ``indices`` spread evenly over them (all when ``k`` is None or >= their number)."""
    if k is None or k >= indices.size:
        return indices
    if k <= 0:
        return indices[:0]
    return indices[np.unique(np.round(np.linspace(0, indices.size - 1, k)).astype(np.int64))]


def replays(
    dataset: HandoverDataset,
    fold_ids: np.ndarray,
    replay_folds: tuple[int, ...],
    paths: dict[str, str],
    max_per_fold: int | None = None,
) -> list[ReceiverSpec]:
    """The replayed episodes of ``replay_folds`` (``max_per_fold`` of each, spread evenly).

    With a recording file the recorded transfer is detected here (once per recording).
    """
    k = int(fold_ids.max()) + 1 if fold_ids.size else 0
    bad = [f for f in replay_folds if not 0 <= f < k]
    if bad:
        raise ValueError(f"--replay-folds {bad}: the split has folds 0..{k - 1}")
    out = []
    for f in replay_folds:
        for i in pick_evenly(np.flatnonzero(fold_ids == f), max_per_fold):
            ep = dataset[int(i)]
            path = paths.get(ep.source_id)
            t_rec, x_rec = recorded_transfer(path) if path else (math.nan, math.nan)
            out.append(
                ReceiverSpec(
                    "replay",
                    ep.source_id,
                    int(i),
                    fold=int(f),
                    index=int(i),
                    path=path,
                    is_ood=ep.is_ood,
                    recorded_transfer_time=t_rec,
                    recorded_pelvis_x=x_rec,
                )
            )
    return out


def other_replays(
    replay: HandoverDataset,
    offset: int,
    paths: dict[str, str],
    max_n: int | None = None,
) -> list[ReceiverSpec]:
    """Every episode of ``replay`` (or ``max_n`` of them, spread evenly) as a replay receiver.

    ``offset`` = the number of training episodes before them (``methods.with_test_data``); the reset
    seed and the index are ``offset + i``; ``fold`` is None (no split: see :data:`FIT_ALL`).
    """
    out = []
    for i in pick_evenly(np.arange(len(replay)), max_n):
        ep = replay[int(i)]
        path = paths.get(ep.source_id)
        t_rec, x_rec = recorded_transfer(path) if path else (math.nan, math.nan)
        out.append(
            ReceiverSpec(
                "replay",
                ep.source_id,
                offset + int(i),
                index=offset + int(i),
                path=path,
                is_ood=ep.is_ood,
                recorded_transfer_time=t_rec,
                recorded_pelvis_x=x_rec,
            )
        )
    return out


def recorded_transfer(path: str) -> tuple[float, float]:
    """``(time s, pelvis x m)`` of the recorded receiver's grasp, NaNs when none is detected."""
    from handover_env.data.detect import detect_transfer
    from handover_env.data.filtering import smooth_track
    from handover_env.person.recording import load_recording

    rec = load_recording(path)
    pose = smooth_track(rec.receiver_pose, RATE_HZ)
    det = detect_transfer(pose, smooth_track(rec.episode.giver_xyz, RATE_HZ), RATE_HZ)
    if det.frame is None:
        return math.nan, math.nan
    return det.frame / RATE_HZ, float(pose[det.frame, 0, 0])


def replay_source(spec: ReceiverSpec, dataset: HandoverDataset):
    """What ``reset(options={"episode": ...})`` replays: the Recording, else the dataset Episode."""
    if spec.path is not None:
        from handover_env.person.recording import load_recording

        return load_recording(spec.path)
    assert spec.index is not None, "a replay spec needs a dataset index"
    return dataset[spec.index]
