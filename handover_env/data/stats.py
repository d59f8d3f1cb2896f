"""Per-episode statistics of a handover dataset, used by ``info`` and ``compare`` and for
calibration.

The same definitions apply to recorded and synthetic data, so the two can be compared directly:

* **walking speed**: the median over frames of the receiver pelvis speed |d(xy)/dt|, m/s;
* **duration**: T / rate, s;
* **transfer**: the frame k* at which the receiver's hand is nearest the object (the giver wrist
  x^g of the paper); in the public recordings the hand-object distance has a sharp minimum there
  and the object then travels on with the receiver;
* **transfer x, y, height**: the object position at k*, m;
* **transfer time fraction**: k* / (T - 1);
* **transfer hand distance**: the hand-object distance at k*, m;
* **start x, y**: the receiver pelvis xy in the first frame, m;
* **giver reach onset**: the first time the object has moved more than
  :data:`REACH_ONSET_DISTANCE` from where it was in the first frame, s.

Comparisons use the two-sample Kolmogorov-Smirnov statistic (:func:`scipy.stats.ks_2samp`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import ks_2samp

from handover_env.data.dataset import HandoverDataset

REACH_ONSET_DISTANCE = 0.03  # m

#: Statistic name -> (label, unit). The order is the printing order.
STATISTICS: dict[str, tuple[str, str]] = {
    "speed": ("walking speed (median per episode)", "m/s"),
    "duration": ("duration", "s"),
    "transfer_z": ("transfer height", "m"),
    "transfer_x": ("transfer x", "m"),
    "transfer_y": ("transfer y", "m"),
    "transfer_fraction": ("transfer time fraction", ""),
    "transfer_distance": ("hand-object distance at transfer", "m"),
    "start_x": ("start x", "m"),
    "start_y": ("start y", "m"),
    "reach_onset": ("giver reach onset", "s"),
}
#: The statistics whose medians the synthetic generator must match within 10% (issue 3).
ACCEPTANCE_STATISTICS = ("speed", "duration", "transfer_z", "transfer_x")


def transfer_index(hand_xyz: np.ndarray, object_xyz: np.ndarray) -> int:
    """The frame at which the hand is nearest the object (first such frame on ties)."""
    return int(np.argmin(np.linalg.norm(np.asarray(hand_xyz) - np.asarray(object_xyz), axis=-1)))


def episode_statistics(dataset: HandoverDataset) -> dict[str, np.ndarray]:
    """Every statistic of :data:`STATISTICS` for every episode, as (N,) arrays, plus ``is_ood``."""
    rate = dataset.rate_hz
    out: dict[str, list[float]] = {name: [] for name in STATISTICS}
    for ep in dataset:
        xy, obj = ep.receiver_xy, ep.giver_xyz
        step = np.linalg.norm(np.diff(xy, axis=0), axis=1) * rate
        k = transfer_index(ep.receiver_hand_xyz, obj)
        moved = np.linalg.norm(obj - obj[0], axis=1) > REACH_ONSET_DISTANCE
        onset = int(np.argmax(moved)) if moved.any() else ep.length - 1
        out["speed"].append(float(np.median(step)))
        out["duration"].append(ep.length / rate)
        out["transfer_z"].append(float(obj[k, 2]))
        out["transfer_x"].append(float(obj[k, 0]))
        out["transfer_y"].append(float(obj[k, 1]))
        out["transfer_fraction"].append(k / (ep.length - 1))
        out["transfer_distance"].append(float(np.linalg.norm(ep.receiver_hand_xyz[k] - obj[k])))
        out["start_x"].append(float(xy[0, 0]))
        out["start_y"].append(float(xy[0, 1]))
        out["reach_onset"].append(onset / rate)
    stats = {name: np.asarray(values, dtype=np.float64) for name, values in out.items()}
    stats["is_ood"] = dataset.ood_mask
    return stats


@dataclass(frozen=True)
class Comparison:
    """One statistic of two datasets side by side.

    Attributes:
        name: key in :data:`STATISTICS`.
        median_a: median over dataset A's episodes.
        median_b: median over dataset B's episodes.
        relative_difference: (median_b - median_a) / |median_a|.
        ks: two-sample Kolmogorov-Smirnov statistic.
        ks_pvalue: its p-value.
    """

    name: str
    median_a: float
    median_b: float
    relative_difference: float
    ks: float
    ks_pvalue: float


def compare_statistics(
    a: dict[str, np.ndarray], b: dict[str, np.ndarray], subset: str = "all"
) -> list[Comparison]:
    """Compare the statistics of two datasets (from :func:`episode_statistics`).

    Args:
        a: statistics of the reference (e.g. the real data).
        b: statistics of the candidate (e.g. the synthetic data).
        subset: ``"all"``, ``"id"`` or ``"ood"`` episodes.
    """
    if subset not in ("all", "id", "ood"):
        raise ValueError(f"subset must be 'all', 'id' or 'ood', got {subset!r}")

    def pick(s: dict[str, np.ndarray], name: str) -> np.ndarray:
        values = s[name]
        if subset == "all":
            return values
        return values[s["is_ood"]] if subset == "ood" else values[~s["is_ood"]]

    rows = []
    for name in STATISTICS:
        va, vb = pick(a, name), pick(b, name)
        if va.size == 0 or vb.size == 0:
            continue
        ma, mb = float(np.median(va)), float(np.median(vb))
        rel = (mb - ma) / abs(ma) if ma != 0 else float("inf")
        ks = ks_2samp(va, vb)
        rows.append(Comparison(name, ma, mb, rel, float(ks.statistic), float(ks.pvalue)))
    return rows


def format_distribution(stats: dict[str, np.ndarray]) -> str:
    """A table of median and 5/25/75/95 % quantiles per statistic, for ID, OOD and all."""
    lines = [
        f"{'statistic':40s} {'subset':6s} {'median':>8s} {'p5':>8s} {'p25':>8s} {'p75':>8s} "
        f"{'p95':>8s}"
    ]
    mask = stats["is_ood"]
    for name, (label, unit) in STATISTICS.items():
        for subset, sel in (("ID", ~mask), ("OOD", mask), ("all", np.ones_like(mask))):
            values = stats[name][sel]
            if values.size == 0:
                continue
            p5, p25, p50, p75, p95 = np.percentile(values, [5, 25, 50, 75, 95])
            title = f"{label} [{unit}]" if unit else label
            lines.append(
                f"{title if subset == 'ID' else '':40s} {subset:6s} "
                f"{p50:8.3f} {p5:8.3f} {p25:8.3f} {p75:8.3f} {p95:8.3f}"
            )
    return "\n".join(lines)


def format_comparison(rows: list[Comparison], name_a: str = "A", name_b: str = "B") -> str:
    """A side-by-side table of medians, relative difference and KS statistic."""
    header = (
        f"{'statistic':40s} {'median ' + name_a:>14s} {'median ' + name_b:>14s} {'rel. diff':>10s} "
        f"{'KS':>6s} {'KS p':>9s}"
    )
    lines = [header]
    for row in rows:
        label, unit = STATISTICS[row.name]
        title = f"{label} [{unit}]" if unit else label
        flag = " *" if row.name in ACCEPTANCE_STATISTICS else ""
        lines.append(
            f"{title:40s} {row.median_a:14.3f} {row.median_b:14.3f} "
            f"{100 * row.relative_difference:+9.1f}% "
            f"{row.ks:6.3f} {row.ks_pvalue:9.2e}{flag}"
        )
    lines.append("* acceptance: medians within 10% (issue 3)")
    return "\n".join(lines)
