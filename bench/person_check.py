"""The simulated person against the recordings, from one closed-loop run's episodes.

Reads ``closed_loop_episodes.csv`` of ``evaluate.py closed-loop`` (a run with replays of a
public-dataset folder) and prints, per agent and receiver set (``walker-id``, ``walker-ood``,
``replay-id``, ``replay-ood``):

* the reach statistic (right shoulder to the object when the person took it, ``reach_distance``,
  episodes with a grasp): median and SD; on replays beside the recorded reach of the same
  recordings (``object_shoulder_transfer``,
  :func:`handover_eval.closedloop.reach_check.reach_agreement`), their ratio, and the median's
  difference with its 95 % bootstrap interval over the recordings (:func:`median_difference_ci`);
* success with its Wilson 95 % interval; on replays the median |Δt| and |Δx| of the grasp against
  the recorded transfer;
* ``missed`` episodes and how many ended before the recorded transfer (replays);
* the deepest penetration, and the episodes with a body-contact force over ``--force`` N, in all
  and by the segment that carried it (an episode counts once per segment over the threshold).

The run's person is whatever ``evaluate.py closed-loop --person`` set (its ``closed_loop.md``
header names it); without ``--person`` the default person.

Usage: ``python bench/person_check.py RUN_FOLDER --data PATH/whole_motions [--force 50]``
"""

from __future__ import annotations

import argparse
import csv
import math
from collections import Counter
from pathlib import Path

import numpy as np

SETS = (("walker-id", "id", None), ("walker-ood", "ood", None),
        ("replay-id", "replay", "False"), ("replay-ood", "replay", "True"))


def _f(value: object) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


def summarise(rows: list[dict[str, str]], recorded: dict[str, dict[str, float]],
              force: float) -> list[dict[str, object]]:
    """One summary per agent and set (module docstring)."""
    from handover_env.person.skeleton import SEGMENTS
    from handover_eval.closedloop.stats import wilson_interval

    out = []
    for agent in dict.fromkeys(r["agent"] for r in rows):
        for label, kind, ood in SETS:
            sel = [r for r in rows if r["agent"] == agent and r["set"] == kind
                   and (ood is None or str(r.get("is_ood")) == ood)]
            if not sel:
                continue
            n = len(sel)
            k = sum(r["outcome"] == "success" for r in sel)
            lo, hi = wilson_interval(k, n)
            reach = np.array([_f(r["reach_distance"]) for r in sel])
            took = reach[reach > 0]
            rec = np.array([recorded.get(r["receiver"], {}).get("object_shoulder_transfer",
                                                                math.nan) for r in sel])
            paired = (reach > 0) & np.isfinite(rec)
            row: dict[str, object] = {
                "agent": agent, "set": label, "n": n, "success": k / n, "ci": (lo, hi),
                "reach_n": int(took.size),
                "reach_median": float(np.median(took)) if took.size else math.nan,
                "reach_sd": float(np.std(took, ddof=1)) if took.size > 1 else math.nan,
                "penetration_max": max(_f(r["penetration"]) for r in sel),
            }
            if kind == "replay":
                row["rec_n"] = int(paired.sum())
                row["sim_median_paired"] = float(np.median(reach[paired]))
                row["rec_median"] = float(np.median(rec[paired]))
                row["median_diff_ci"] = median_difference_ci(reach[paired], rec[paired])
                row["sim_sd_paired"] = float(np.std(reach[paired], ddof=1))
                row["rec_sd"] = float(np.std(rec[paired], ddof=1))
                dt = np.abs([_f(r["delta_t"]) for r in sel])
                dx = np.abs([_f(r["delta_x"]) for r in sel])
                row["abs_dt_median"] = float(np.nanmedian(dt))
                row["abs_dx_median"] = float(np.nanmedian(dx))
                missed = [r for r in sel if r["outcome"] == "missed"]
                row["missed"] = len(missed)
                row["missed_before_transfer"] = sum(
                    _f(r["time"]) < _f(r["recorded_transfer_time"]) for r in missed)
            over = [r for r in sel if _f(r["body_contact_force"]) > force]
            row["contact_over"] = len(over)
            row["contact_max"] = max(_f(r["body_contact_force"]) for r in sel)
            by_segment: Counter[str] = Counter()
            for r in over:
                for s in SEGMENTS:
                    if _f(r.get(f"contact_force_{s.name}")) > force:
                        by_segment[s.name] += 1
            row["contact_by_segment"] = dict(by_segment.most_common())
            row["outcomes"] = dict(Counter(r["outcome"] for r in sel).most_common())
            out.append(row)
    return out


def median_difference_ci(sim: np.ndarray, rec: np.ndarray, reps: int = 10_000,
                         seed: int = 0) -> tuple[float, float, float]:
    """``(d, low, high)``: the simulated minus the recorded median over the same recordings, and
    its 95 % percentile interval over ``reps`` bootstrap resamples of the recordings (each
    resample keeps a recording's simulated and recorded reach together)."""
    sim, rec = np.asarray(sim, dtype=np.float64), np.asarray(rec, dtype=np.float64)
    if sim.shape != rec.shape or sim.ndim != 1 or sim.size < 2:
        return math.nan, math.nan, math.nan
    idx = np.random.default_rng(seed).integers(0, sim.size, size=(reps, sim.size))
    diffs = np.median(sim[idx], axis=1) - np.median(rec[idx], axis=1)
    low, high = np.percentile(diffs, [2.5, 97.5])
    return float(np.median(sim) - np.median(rec)), float(low), float(high)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="an evaluate.py closed-loop output folder")
    p.add_argument("--data", required=True, help="the public-dataset folder the run replayed")
    p.add_argument("--force", type=float, default=50.0, help="body-contact threshold, N")
    args = p.parse_args()
    from handover_eval.closedloop.reach_check import recorded_measures

    with open(Path(args.run) / "closed_loop_episodes.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    names = {r["receiver"] for r in rows if r["set"] == "replay"}
    recorded = recorded_measures(args.data, names)
    for s in summarise(rows, recorded, args.force):
        lo, hi = s["ci"]
        line = (f"{s['agent']:>13} {s['set']:<10} n={s['n']:<4} success {s['success']:.3f} "
                f"[{lo:.3f}, {hi:.3f}]  reach n={s['reach_n']} median {s['reach_median']:.3f} "
                f"SD {s['reach_sd']:.3f}")
        if "rec_sd" in s:
            line += (f" | paired n={s['rec_n']} sim {s['sim_median_paired']:.3f}/"
                     f"{s['sim_sd_paired']:.3f} rec {s['rec_median']:.3f}/{s['rec_sd']:.3f} "
                     f"SD ratio {s['sim_sd_paired'] / s['rec_sd']:.2f}  median sim - rec "
                     f"{s['median_diff_ci'][0]:+.3f} [{s['median_diff_ci'][1]:+.3f}, "
                     f"{s['median_diff_ci'][2]:+.3f}] m  |dt| "
                     f"{s['abs_dt_median']:.3f} s |dx| {s['abs_dx_median']:.3f} m  missed "
                     f"{s['missed']} ({s['missed_before_transfer']} before the transfer)")
        line += (f" | penetration max {1000 * s['penetration_max']:.1f} mm | contact > "
                 f"{args.force:g} N: {s['contact_over']} (max {s['contact_max']:.0f} N) "
                 f"{s['contact_by_segment']} | {s['outcomes']}")
        print(line)


if __name__ == "__main__":
    main()
