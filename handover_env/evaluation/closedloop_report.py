"""Tables of the closed-loop evaluation: aggregates per agent and receiver set, paired comparisons
against the reactive agent, and the "no ghosts" summary (Markdown + CSV).

Populations: a success rate is over all episodes (95 % Wilson CI); handover time is over the
successes; transfer position and release force over the episodes where they exist (a grasp, a
release); contact forces, receiver effort and robot jerk over all episodes (the effort of a
failed handover counts too). Paired differences are agent - reactive on the same receivers
(same set and receiver key), over the pairs where both values exist (handover time: both
succeeded), with a seeded bootstrap CI that resamples pairs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from handover_env.evaluation.closedloop_agents import LABELS
from handover_env.evaluation.closedloop_stats import (
    N_BOOTSTRAP,
    median_iqr,
    pair_up,
    paired_difference,
    quantiles,
    stable_seed,
    wilson_interval,
)
from handover_env.evaluation.reporting import markdown_table

OUTCOMES = ("success", "premature_release", "dropped", "unsafe_force", "missed", "timeout")
EFFORT = (
    "reach_distance",
    "arm_extended_time",
    "time_lost",
    "min_speed_factor",
    "path_deviation",
    "pull_force",
)
#: column -> (label, unit, digits) of the per-episode quantities summarised by median [IQR].
QUANTITIES: dict[str, tuple[str, str, int]] = {
    "handover_time": ("handover time", "s", 2),
    "transfer_time": ("transfer (grasp) time", "s", 2),
    "transfer_pelvis_x": ("pelvis x at the grasp", "m", 2),
    "release_force": ("release force", "N", 1),
    "peak_contact_force": ("peak contact force (wrist or body)", "N", 1),
    "body_contact_force": ("peak robot-body contact force", "N", 1),
    "reach_distance": ("reach distance", "m", 2),
    "arm_extended_time": ("arm extended", "s", 2),
    "time_lost": ("time lost slowing down", "s", 2),
    "min_speed_factor": ("slowest speed factor", "", 2),
    "path_deviation": ("path deviation", "m", 3),
    "pull_force": ("pull force", "N", 1),
    "robot_jerk_rms": ("robot jerk RMS", "m/s³", 0),
    "robot_jerk_peak": ("robot jerk peak", "m/s³", 0),
}
#: metric -> (row column, statistic) of the paired comparisons.
PAIRED: dict[str, tuple[str, str]] = {
    "success": ("is_success", "mean"),
    "handover_time": ("handover_time", "median"),
    **{m: (m, "median") for m in EFFORT},
    "peak_contact_force": ("peak_contact_force", "median"),
    "body_contact_force": ("body_contact_force", "median"),
    "robot_jerk_rms": ("robot_jerk_rms", "median"),
}
NOTE_SIMULATED = (
    "These results come from the **simulated person** (an articulated, compliant body whose "
    "reaching and grasping are calibrated to the recorded human-human handovers), not from people."
)
NOTE_TIME = (
    "Handover time is the paper's (Sec. V-C): from when the receiver leaves the start point to the "
    "gripper release, successes only; the static baseline's 2 s stabilisation delay is excluded "
    "(`handover_time_with_delay` in the CSV includes it). Scripted walkers start at rest. "
    "Recordings start mid-walk, so on replays it runs from the start of the recording (the "
    "receiver is already moving: departure = 0) to the release."
)


def _value(row: dict, column: str) -> float:
    v = row.get(column)
    if isinstance(v, bool):
        return float(v)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _group(rows: Sequence[dict]) -> dict[tuple[str, str], list[dict]]:
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["agent"], r["set"]), []).append(r)
    return groups


def aggregate(rows: Sequence[dict]) -> list[dict]:
    """One row per (agent, receiver set), in first-seen order (module docstring)."""
    out = []
    for (agent, rset), mine in _group(rows).items():
        n = len(mine)
        k = sum(1 for r in mine if r["outcome"] == "success")
        lo, hi = wilson_interval(k, n)
        row: dict = {
            "agent": agent,
            "set": rset,
            "n": n,
            "success_rate": k / n,
            "success_low": lo,
            "success_high": hi,
        }
        row.update({f"n_{o}": sum(1 for r in mine if r["outcome"] == o) for o in OUTCOMES})
        for col in QUANTITIES:
            vals = np.array([_value(r, col) for r in mine])
            row[f"{col}_n"] = int(np.isfinite(vals).sum())
            row[f"{col}_median"], row[f"{col}_q25"], row[f"{col}_q75"] = median_iqr(vals)
        pen = np.array([_value(r, "penetration") for r in mine])
        row["penetration_max"] = float(np.nanmax(pen)) if np.isfinite(pen).any() else math.nan
        row["release_before_grasp_successes"] = sum(
            1 for r in mine if r["outcome"] == "success" and bool(r.get("release_before_grasp"))
        )
        if rset == "replay":
            dt = np.array([_value(r, "delta_t") for r in mine])
            dx = np.array([_value(r, "delta_x") for r in mine])
            row["n_delta"] = int(np.isfinite(dt).sum())
            row["abs_delta_t_median"], row["abs_delta_t_q25"], row["abs_delta_t_q75"] = median_iqr(
                np.abs(dt)
            )
            row["abs_delta_x_median"], row["abs_delta_x_q25"], row["abs_delta_x_q75"] = median_iqr(
                np.abs(dx)
            )
            row["delta_t_median"], row["delta_x_median"] = median_iqr(dt)[0], median_iqr(dx)[0]
        out.append(row)
    return out


def paired(
    rows: Sequence[dict],
    reference: str = "reactive",
    n_boot: int = N_BOOTSTRAP,
    seed: int = 0,
    metrics: dict[str, tuple[str, str]] = PAIRED,
) -> list[dict]:
    """Every agent against ``reference`` on the same receivers, per set and metric."""
    groups = _group(rows)
    out = []
    for (agent, rset), mine in groups.items():
        ref = groups.get((reference, rset))
        if agent == reference or ref is None:
            continue
        out += paired_metrics(mine, ref, {"agent": agent, "set": rset}, n_boot, seed, metrics)
    return out


def paired_metrics(
    rows: Sequence[dict],
    ref_rows: Sequence[dict],
    head: dict,
    n_boot: int = N_BOOTSTRAP,
    seed: int = 0,
    metrics: dict[str, tuple[str, str]] = PAIRED,
) -> list[dict]:
    """Paired differences ``rows - ref_rows`` matched on (set, receiver), one dict per metric."""
    out = []
    for metric, (column, stat) in metrics.items():
        a = {(r["set"], r["receiver"]): _value(r, column) for r in rows}
        b = {(r["set"], r["receiver"]): _value(r, column) for r in ref_rows}
        _, x, y = pair_up(a, b)
        d = paired_difference(x, y, stat, n_boot, stable_seed(*head.values(), metric, base=seed))
        out.append(
            {
                **head,
                "metric": metric,
                "stat": stat,
                "n_pairs": d.n,
                "agent_value": d.agent,
                "reference_value": d.reference,
                "diff": d.diff,
                "diff_low": d.low,
                "diff_high": d.high,
                "ci_excludes_zero": d.excludes_zero,
            }
        )
    return out


def ghosts(rows: Sequence[dict]) -> list[dict]:
    """The "no ghosts" summary, over all episodes and per agent."""
    out = []
    for agent in ["all", *dict.fromkeys(r["agent"] for r in rows)]:
        mine = [r for r in rows if agent in ("all", r["agent"])]
        pen = np.array([_value(r, "penetration") for r in mine])
        body = np.array([_value(r, "body_contact_force") for r in mine])
        peak = np.array([_value(r, "peak_contact_force") for r in mine])
        row = {
            "agent": agent,
            "n": len(mine),
            "max_penetration_m": float(np.nanmax(pen)) if mine else math.nan,
            "episodes_penetration_over_1cm": int((pen > 0.01).sum()),
            "successes_release_before_grasp": sum(
                1 for r in mine if r["outcome"] == "success" and bool(r.get("release_before_grasp"))
            ),
            "episodes_with_body_contact": int((body > 0).sum()),
        }
        for name, vals in (("body_contact_force", body), ("peak_contact_force", peak)):
            for q, v in zip(("q50", "q90", "q99", "max"), quantiles(vals), strict=True):
                row[f"{name}_{q}"] = v
        out.append(row)
    return out


# ------------------------------------------------------------------------------------ markdown
def _f(v: float, digits: int) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def med_iqr(row: dict, col: str, digits: int) -> str:
    """'1.23 [1.01, 1.50]' from an aggregate row, '–' when undefined."""
    m = row.get(f"{col}_median", math.nan)
    if not math.isfinite(m):
        return "–"
    return f"{_f(m, digits)} [{_f(row[f'{col}_q25'], digits)}, {_f(row[f'{col}_q75'], digits)}]"


def success_cell(row: dict) -> str:
    """'95 % [88, 98]': the success rate of an aggregate row with its Wilson CI."""
    return (
        f"{100 * row['success_rate']:.0f} % "
        f"[{100 * row['success_low']:.0f}, {100 * row['success_high']:.0f}]"
    )


def outcomes_cell(row: dict) -> str:
    short = {"premature_release": "premature", "unsafe_force": "unsafe"}
    parts = [f"{short.get(o, o)} {row[f'n_{o}']}" for o in OUTCOMES[1:] if row[f"n_{o}"]]
    return ", ".join(parts) or "–"


def _diff_cell(d: dict, digits: int) -> str:
    if not d["n_pairs"]:
        return "–"
    star = " *" if d["ci_excludes_zero"] else ""
    return (
        f"{d['diff']:+.{digits}f} [{d['diff_low']:+.{digits}f}, {d['diff_high']:+.{digits}f}]{star}"
    )


def markdown(
    agg: list[dict], pairs: list[dict], ghost: list[dict], header: str, footer: str = ""
) -> str:
    """The whole closed_loop.md."""

    def lab(r: dict) -> str:
        return LABELS.get(r["agent"], r["agent"])

    t1 = markdown_table(
        [
            "agent",
            "set",
            "n",
            "success [95 % CI]",
            "other outcomes",
            "handover time (s)",
            "grasp pelvis x (m)",
            "release force (N)",
            "peak body contact (N)",
            "max penetration (mm)",
        ],
        [
            [
                lab(r),
                r["set"],
                r["n"],
                success_cell(r),
                outcomes_cell(r),
                med_iqr(r, "handover_time", 2),
                med_iqr(r, "transfer_pelvis_x", 2),
                med_iqr(r, "release_force", 1),
                med_iqr(r, "body_contact_force", 1),
                _f(1000 * r["penetration_max"], 1),
            ]
            for r in agg
        ],
    )
    t2 = markdown_table(
        [
            "agent",
            "set",
            "reach (m)",
            "arm extended (s)",
            "time lost (s)",
            "slowest speed",
            "path dev. (m)",
            "pull (N)",
            "jerk RMS (m/s³)",
        ],
        [
            [
                lab(r),
                r["set"],
                *(med_iqr(r, c, QUANTITIES[c][2]) for c in EFFORT),
                med_iqr(r, "robot_jerk_rms", 0),
            ]
            for r in agg
        ],
    )
    text = header + "\n" + NOTE_SIMULATED + "\n\n## Success, outcomes, timing and forces\n\n" + t1
    text += (
        "\nMedian [25 %, 75 %]. "
        + NOTE_TIME
        + "\n\n## Receiver effort and robot smoothness\n\n"
        + t2
    )
    text += (
        "\nAll episodes (a failed handover's effort counts too). Reach: the largest grip-shoulder "
        "distance; arm extended: time with the arm out before the release; time lost: walking "
        "time lost to slowing down; slowest speed: the lowest walking-speed factor (1 = never "
        "slowed); path deviation: how far contact pushed the pelvis off its path; pull: the "
        "largest pull while both held the object; jerk: the robot TCP's jerk at 30 Hz.\n"
    )
    reps = [r for r in agg if r["set"] == "replay" and r.get("n_delta")]
    if reps:
        text += "\n## Simulated vs recorded transfer (replays)\n\n" + markdown_table(
            [
                "agent",
                "recordings with a detected transfer",
                "median |Δt| (s)",
                "median |Δx| (m)",
                "median Δt (s)",
                "median Δx (m)",
            ],
            [
                [
                    lab(r),
                    r["n_delta"],
                    med_iqr(r, "abs_delta_t", 2),
                    med_iqr(r, "abs_delta_x", 2),
                    _f(r["delta_t_median"], 2),
                    _f(r["delta_x_median"], 2),
                ]
                for r in reps
            ],
        )
        text += (
            "\nΔt = simulated grasp time - recorded transfer time (both from the start of the "
            "recording); Δx = simulated - recorded pelvis x at the grasp. The giver-replay agent "
            "moves the object along the recorded giver's path, so its Δ says whether the "
            "simulated person takes the object when and where the recorded one did.\n"
        )
    if pairs:
        cols = ["success", "handover_time", *EFFORT, "body_contact_force", "robot_jerk_rms"]
        digits = {
            "success": 2,
            "handover_time": 2,
            "pull_force": 1,
            "body_contact_force": 1,
            "robot_jerk_rms": 0,
            "path_deviation": 3,
        }
        by = {(d["agent"], d["set"], d["metric"]): d for d in pairs}
        keys = list(dict.fromkeys((d["agent"], d["set"]) for d in pairs))
        text += "\n## Paired against the reactive agent (agent - reactive, same receivers)\n\n"
        text += markdown_table(
            ["agent", "set", "n", *[c.replace("_", " ") for c in cols]],
            [
                [
                    LABELS.get(a, a),
                    s,
                    by[(a, s, "success")]["n_pairs"],
                    *(_diff_cell(by[(a, s, c)], digits.get(c, 2)) for c in cols),
                ]
                for a, s in keys
            ],
        )
        text += (
            "\nSuccess: difference in success rate; the others: median paired difference (handover "
            "time over the receivers both handed over to); [95 % bootstrap CI over receivers]; "
            "* = the CI excludes 0. Full table with n per metric: `closed_loop_paired.csv`.\n"
        )
    text += "\n## No ghosts\n\n" + markdown_table(
        [
            "agent",
            "episodes",
            "max penetration (mm)",
            "> 1 cm",
            "successes released before the grasp",
            "with body contact",
            "body contact q50/q90/q99/max (N)",
            "peak contact q50/q90/q99/max (N)",
        ],
        [
            [
                LABELS.get(g["agent"], g["agent"]),
                g["n"],
                _f(1000 * g["max_penetration_m"], 1),
                g["episodes_penetration_over_1cm"],
                g["successes_release_before_grasp"],
                g["episodes_with_body_contact"],
                "/".join(_f(g[f"body_contact_force_{q}"], 0) for q in ("q50", "q90", "q99", "max")),
                "/".join(_f(g[f"peak_contact_force_{q}"], 0) for q in ("q50", "q90", "q99", "max")),
            ]
            for g in ghost
        ],
    )
    return text + "\n" + footer
