"""The open-loop RMS protocol (paper Sec. V-A, Table I and the sample-efficiency / trade-off
figures).

Every method (SPGP planner, IAAL, BC-MLP, ACT, ...) is scored by this one protocol:

* **Queries.** For a test episode of length L, the method is queried at frames
  ``t_c in range(first_query, L - 1, stride)`` (defaults: ``first_query = 5`` frames of history
  before the first query, ``stride = 1``, i.e. every frame but the last). At t_c it sees the
  receiver base track ``receiver_xy[: t_c + 1]`` (30 Hz, oldest first) and nothing else of the
  test episode (through :meth:`Agent.predict_episode`). The one exception is documented per
  agent: the learned baselines (BC-MLP, ACT) also read the giver position at frame t_c as their
  ``observation.state`` (a robot knows where its own hand is), never a later row.
* **Prediction.** It returns (H, 3) giver wrist positions, ``H = horizon = 30`` frames (1 s, the
  paper's chunk); row 0 is the giver position at frame t_c itself, row i at t_c + i.
* **Ground truth** is ``giver_xyz[t_c : t_c + H]``; near the end of the episode fewer than H rows
  exist and only the available rows are compared.
* **Per-episode RMS** = sqrt(mean over all compared rows of all queries of the squared 3D
  Euclidean error), in millimetres (``rms_3d_mm``). The paper does not say whether it reports
  the 3D error or the error per coordinate, so both are given: ``rms_axis_mm = rms_3d_mm /
  sqrt(3)`` is the RMS over the x, y and z components.
* **Current-frame error** (``rms_now_axis_mm``): the same errors restricted to row 0 (the giver
  position at t_c itself, the pose the robot is asked to be at now), as RMS per coordinate. This is
  the reading of the paper's Table I that our numbers match: on the 875-episode development copy
  the planner scores 53.69 +- 1.69 (ID) / 60.81 +- 8.33 (OOD) mm on it against the paper's
  55.13 +- 2.48 / 61.83 +- 5.32, while the full 1 s horizon gives ~111 / ~152 mm in 3D. The paper
  does not state its metric, so both are reported and neither is called "the" Table I figure.
* **Displacement errors** (``ade_05_mm``, ``fde_05_mm``, ``ade_10_mm``, ``fde_10_mm``, the
  trajectory-prediction metrics): the mean 3D Euclidean error over the future rows 1 .. K of the
  chunk (ADE) and the error at row K (FDE), for K = 15 (0.5 s ahead) and K = 29 (1 s: the 30-row
  chunk's last row, 29 / 30 s ahead), in millimetres; each over the queries whose rows exist in
  the episode (NaN when none does).
* **Summary.** :func:`summarise` gives the mean and standard deviation over episodes, for ID and
  OOD episodes separately. **k-fold** (:func:`kfold_rms`, the paper's stratified 10-fold):
  :meth:`HandoverDataset.stratified_kfold` splits ID and OOD episodes separately; for each fold
  a fresh agent is fitted on the other folds and every test episode is scored; the reported
  figure is mean +- std over the k folds of the per-fold mean episode RMS (ID and OOD apart).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from agents.base import Agent
from handover_env.data.dataset import Episode, HandoverDataset

SQRT3 = math.sqrt(3.0)
#: (name, seconds ahead) of the displacement errors; row K = round(seconds * 30), at most H - 1.
DISPLACEMENT_HORIZONS: tuple[tuple[str, float], ...] = (("05", 0.5), ("10", 1.0))
RATE_HZ = 30.0


@dataclass(frozen=True)
class OpenLoopProtocol:
    """Settings of the open-loop protocol (see the module docstring).

    Args:
        horizon: H, predicted and compared frames per query (30 = 1 s at 30 Hz).
        first_query: frames of history before the first query (the first query is at this frame).
        stride: frames between queries.
    """

    horizon: int = 30
    first_query: int = 5
    stride: int = 1

    def __post_init__(self) -> None:
        for name, low in (("horizon", 1), ("first_query", 0), ("stride", 1)):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {v!r}")

    def to_dict(self) -> dict:
        return {k: int(v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class EpisodeRecord:
    """Score of one test episode."""

    source_id: str
    is_ood: bool
    rms_3d_mm: float
    rms_axis_mm: float
    n_queries: int
    n_rows: int
    rms_now_axis_mm: float = float("nan")  # row 0 only, RMS per coordinate (see the module doc)
    ade_05_mm: float = float("nan")
    fde_05_mm: float = float("nan")
    ade_10_mm: float = float("nan")
    fde_10_mm: float = float("nan")


def query_times(length: int, protocol: OpenLoopProtocol = OpenLoopProtocol()) -> np.ndarray:
    """Frames at which an episode of ``length`` frames is queried (may be empty)."""
    if length < 0:
        raise ValueError(f"length must be >= 0, got {length}")
    return np.arange(protocol.first_query, length - 1, protocol.stride, dtype=np.int64)


def episode_rms(
    agent: Agent, episode: Episode, protocol: OpenLoopProtocol = OpenLoopProtocol()
) -> tuple[float, int]:
    """(rms_3d_mm, number of compared rows) of one episode; NaN and 0 when it has no query."""
    rms, _, n = episode_errors(agent, episode, protocol)
    return rms, n


def episode_errors(
    agent: Agent, episode: Episode, protocol: OpenLoopProtocol = OpenLoopProtocol()
) -> tuple[float, float, int]:
    """(rms_3d_mm over the horizon, rms_now_axis_mm of row 0, compared rows) of one episode.

    NaN, NaN and 0 when the episode has no query.
    """
    m = episode_metrics(agent, episode, protocol)
    return m["rms_3d_mm"], m["rms_now_axis_mm"], int(m["n_rows"])


def displacement_row(seconds: float, horizon: int) -> int:
    """Row K of the chunk that lies ``seconds`` ahead (at most the last row, ``horizon - 1``)."""
    return max(1, min(int(round(seconds * RATE_HZ)), horizon - 1))


def episode_metrics(
    agent: Agent, episode: Episode, protocol: OpenLoopProtocol = OpenLoopProtocol()
) -> dict[str, float]:
    """Every open-loop metric of one episode from one set of predictions (module docstring).

    Keys: ``rms_3d_mm``, ``rms_now_axis_mm``, ``ade_05_mm``, ``fde_05_mm``, ``ade_10_mm``,
    ``fde_10_mm`` (mm) and ``n_rows`` (compared rows); NaNs and 0 rows without a query.
    """
    nan = float("nan")
    times = query_times(episode.length, protocol)
    out = {"rms_3d_mm": nan, "rms_now_axis_mm": nan, "n_rows": 0.0}
    out.update({f"{k}_{n}_mm": nan for n, _ in DISPLACEMENT_HORIZONS for k in ("ade", "fde")})
    if times.size == 0:
        return out
    pred = np.asarray(agent.predict_episode(episode, times), dtype=np.float64)
    if (
        pred.shape[0] != times.size
        or pred.ndim != 3
        or pred.shape[2] != 3
        or pred.shape[1] < protocol.horizon
    ):
        raise ValueError(
            f"agent returned predictions of shape {pred.shape}, need ({times.size}, >= "
            f"{protocol.horizon}, 3)"
        )
    if not np.all(np.isfinite(pred)):
        raise ValueError(f"agent returned NaN/inf predictions on episode {episode.source_id!r}")
    giver = episode.giver_xyz
    rows = times[:, None] + np.arange(protocol.horizon)[None, :]  # (Q, H)
    valid = rows < episode.length
    err2 = np.sum(
        (pred[:, : protocol.horizon] - giver[np.minimum(rows, episode.length - 1)]) ** 2, axis=2
    )
    n = int(valid.sum())
    out["rms_now_axis_mm"] = float(np.sqrt(err2[:, 0].mean() / 3.0) * 1000.0)  # t_c < L: row 0
    out["rms_3d_mm"] = float(np.sqrt(err2[valid].mean()) * 1000.0)
    out["n_rows"] = float(n)
    dist = np.sqrt(err2) * 1000.0
    for name, seconds in DISPLACEMENT_HORIZONS:
        k = displacement_row(seconds, protocol.horizon)
        future = valid[:, 1 : k + 1]
        if future.any():
            out[f"ade_{name}_mm"] = float(dist[:, 1 : k + 1][future].mean())
        if valid[:, k].any():
            out[f"fde_{name}_mm"] = float(dist[valid[:, k], k].mean())
    return out


def evaluate_openloop(
    agent: Agent,
    dataset: HandoverDataset,
    protocol: OpenLoopProtocol = OpenLoopProtocol(),
    progress: bool = True,
) -> list[EpisodeRecord]:
    """Score a fitted agent on every episode of ``dataset`` (episodes without a query are
    skipped)."""
    records = []
    start = time.perf_counter()
    for i, ep in enumerate(dataset):
        m = episode_metrics(agent, ep, protocol)
        if m["n_rows"] == 0:
            continue
        records.append(
            EpisodeRecord(
                ep.source_id,
                ep.is_ood,
                m["rms_3d_mm"],
                m["rms_3d_mm"] / SQRT3,
                int(query_times(ep.length, protocol).size),
                int(m["n_rows"]),
                m["rms_now_axis_mm"],
                *(m[f"{k}_{n}_mm"] for n, _ in DISPLACEMENT_HORIZONS for k in ("ade", "fde")),
            )
        )
        if progress and (i + 1) % 50 == 0:
            print(
                f"  open-loop {i + 1}/{len(dataset)} episodes, {time.perf_counter() - start:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    return records


def _mean_std(values: list[float]) -> tuple[float, float]:
    if not values:
        return float("nan"), float("nan")
    arr = np.asarray(values, dtype=np.float64)
    return float(arr.mean()), float(arr.std(ddof=1)) if arr.size > 1 else 0.0


def summarise(records: list[EpisodeRecord]) -> dict[str, dict[str, float]]:
    """Mean and std (over episodes) of the RMS, ID and OOD apart.

    Returns ``{"id": {...}, "ood": {...}, "all": {...}}`` each with ``rms_3d_mm``,
    ``rms_3d_std``, ``rms_axis_mm``, ``rms_axis_std``, ``rms_now_axis_mm``, ``rms_now_axis_std``
    and ``n_episodes``.
    """
    out = {}
    for name, keep in (
        ("id", lambda r: not r.is_ood),
        ("ood", lambda r: r.is_ood),
        ("all", lambda r: True),
    ):
        sel = [r.rms_3d_mm for r in records if keep(r)]
        m, s = _mean_std(sel)
        now_m, now_s = _mean_std([r.rms_now_axis_mm for r in records if keep(r)])
        out[name] = {
            "rms_3d_mm": m,
            "rms_3d_std": s,
            "rms_axis_mm": m / SQRT3,
            "rms_axis_std": s / SQRT3,
            "rms_now_axis_mm": now_m,
            "rms_now_axis_std": now_s,
            "n_episodes": len(sel),
        }
    return out


def kfold_rms(
    make_agent: Callable[[], Agent],
    dataset: HandoverDataset,
    k: int = 10,
    seed: int = 0,
    protocol: OpenLoopProtocol = OpenLoopProtocol(),
    folds: list[int] | None = None,
    progress: bool = True,
) -> dict:
    """Stratified k-fold open-loop RMS: mean +- std over folds of the per-fold mean episode RMS.

    Args:
        make_agent: returns a fresh, unfitted agent.
        dataset: the whole dataset; split with ``dataset.stratified_kfold(k, seed)``.
        k, seed: the split.
        protocol: the open-loop protocol.
        folds: evaluate only these fold indices (quick checks); None = all k.
        progress: print one line per fold to stderr.

    Returns:
        ``{"id": (mean, std), "ood": (mean, std)}`` in mm 3D, the same per-axis under
        ``"id_axis"``/``"ood_axis"``, the current-frame per-axis RMS under
        ``"id_now_axis"``/``"ood_now_axis"``, ``"per_fold"`` (list of :func:`summarise` dicts) and
        ``"records"`` (all episode records).
    """
    splits = dataset.stratified_kfold(k, seed)
    chosen = list(range(k)) if folds is None else list(folds)
    per_fold, records = [], []
    for f in chosen:
        train, test = splits[f]
        t0 = time.perf_counter()
        agent = make_agent().fit(dataset.subset(train))
        recs = evaluate_openloop(agent, dataset.subset(test), protocol, progress=False)
        summ = summarise(recs)
        per_fold.append(summ)
        records.extend(recs)
        if progress:
            print(
                f"  fold {f}: ID {summ['id']['rms_3d_mm']:.2f} mm, OOD "
                f"{summ['ood']['rms_3d_mm']:.2f} mm "
                f"(3D), {time.perf_counter() - t0:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    out: dict = {"per_fold": per_fold, "records": records, "k": k, "seed": seed, "folds": chosen}
    for name in ("id", "ood"):
        vals = [s[name]["rms_3d_mm"] for s in per_fold if s[name]["n_episodes"] > 0]
        m, s = _mean_std(vals)
        out[name] = (m, s)
        out[f"{name}_axis"] = (m / SQRT3, s / SQRT3)
        out[f"{name}_now_axis"] = _mean_std(
            [s_[name]["rms_now_axis_mm"] for s_ in per_fold if s_[name]["n_episodes"] > 0]
        )
    return out
