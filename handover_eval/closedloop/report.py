"""Tables of the closed-loop evaluation: aggregates per agent and receiver group, paired
comparisons against the reactive agent, and the "no ghosts" summary (Markdown + CSV).

Receiver groups (:data:`GROUPS`, the ``set`` column of every table): ``walker-id`` and
``walker-ood`` (the scripted walkers), ``replay-id`` and ``replay-ood`` (the replayed recordings
split by ``is_ood``) and ``replay-all`` (every replay, as one set). A replay row counts in its
``replay-id``/``replay-ood`` group and in ``replay-all``; ID and OOD are never pooled otherwise
(a failure on a third of the ~35 OOD replays among 435 moves the pooled rate by 3 points only).

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

from handover_eval import roster
from handover_eval.closedloop.stats import (
    N_BOOTSTRAP,
    median_iqr,
    pair_up,
    paired_difference,
    quantiles,
    stable_seed,
    wilson_interval,
)
from handover_eval.receivers import SETS

#: Every outcome a row can have: the env's ("unstable": MuJoCo reset a diverging simulation), and
#: "timeout" for a TimeLimit truncation.
OUTCOMES = (
    "success", "premature_release", "dropped", "unsafe_force", "missed", "unstable", "timeout"
)
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
    "hold_time": ("shared hold (grasp to release)", "s", 3),
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
    "body_contact": ("body_contact", "mean"),
    "body_contact_force": ("body_contact_force", "median"),
    "robot_jerk_rms": ("robot_jerk_rms", "median"),
}


def _value(row: dict, column: str) -> float:
    v = row.get(column)
    if isinstance(v, bool):
        return float(v)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


#: The receiver groups of the tables, in table order.
GROUPS: tuple[str, ...] = ("walker-id", "walker-ood", "replay-id", "replay-ood", "replay-all")


def is_ood(row: dict) -> bool:
    """A row's ``is_ood`` (a bool, or its CSV text)."""
    v = row.get("is_ood")
    return v.strip().lower() in ("true", "1") if isinstance(v, str) else bool(v)


def groups_of(row: dict) -> tuple[str, ...]:
    """The receiver groups an episode row counts in (module docstring)."""
    rset = row["set"]
    if rset == "replay":
        return ("replay-ood" if is_ood(row) else "replay-id", "replay-all")
    if rset in SETS:
        return (f"walker-{rset}",)
    raise ValueError(f"unknown receiver set {rset!r}; the rows' sets are {list(SETS)}")


def _order(agent: str, group: str = "") -> tuple[int, int]:
    """Table order: the agents in roster order (:func:`handover_eval.roster.rank`), then the
    groups as in GROUPS."""
    a = roster.rank(agent)
    return a, GROUPS.index(group) if group in GROUPS else len(GROUPS)


def _group(rows: Sequence[dict]) -> dict[tuple[str, str], list[dict]]:
    """(agent, receiver group) -> its rows, in table order."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        for g in groups_of(r):
            groups.setdefault((r["agent"], g), []).append(r)
    return dict(sorted(groups.items(), key=lambda kv: _order(*kv[0])))


def aggregate(rows: Sequence[dict]) -> list[dict]:
    """One row per (agent, receiver group), agents in roster order (module docstring)."""
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
        if rset.startswith("replay"):
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
    """Every agent against ``reference`` on the same receivers, per receiver group and metric."""
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
    """Paired differences ``rows - ref_rows`` matched on (set, receiver), one dict per metric.

    Besides the metric's own statistic (``diff``), every row has the mean paired difference and
    its CI (``mean_*``): the medians of zero-inflated measures (time lost, contact force) are
    often 0 even when the agent changes how often they occur.
    """
    out = []
    for metric, (column, stat) in metrics.items():
        a = {(r["set"], r["receiver"]): _value(r, column) for r in rows}
        b = {(r["set"], r["receiver"]): _value(r, column) for r in ref_rows}
        _, x, y = pair_up(a, b)
        seed_k = stable_seed(*head.values(), metric, base=seed)
        d = paired_difference(x, y, stat, n_boot, seed_k)
        m = d if stat == "mean" else paired_difference(x, y, "mean", n_boot, seed_k)
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
                "mean_diff": m.diff,
                "mean_low": m.low,
                "mean_high": m.high,
                "mean_excludes_zero": m.excludes_zero,
            }
        )
    return out


def ghosts(rows: Sequence[dict]) -> list[dict]:
    """The "no ghosts" summary: over all episodes, then per agent, each over all its receivers
    (``set`` "all") and per receiver group."""
    out = []
    present = [g for g in GROUPS if any(g in groups_of(r) for r in rows)]
    for agent in ["all", *sorted(dict.fromkeys(r["agent"] for r in rows), key=_order)]:
        for group in ["all", *present]:
            mine = [
                r for r in rows
                if agent in ("all", r["agent"]) and (group == "all" or group in groups_of(r))
            ]
            if mine:
                out.append(_ghost_row(agent, group, mine))
    return out


def _ghost_row(agent: str, group: str, mine: list[dict]) -> dict:
    """One row of :func:`ghosts`."""
    pen = np.array([_value(r, "penetration") for r in mine])
    body = np.array([_value(r, "body_contact_force") for r in mine])
    peak = np.array([_value(r, "peak_contact_force") for r in mine])
    row = {
        "agent": agent,
        "set": group,
        "n": len(mine),
        "max_penetration_m": float(np.nanmax(pen)) if np.isfinite(pen).any() else math.nan,
        "episodes_penetration_over_1cm": int((pen > 0.01).sum()),
        "successes_release_before_grasp": sum(
            1 for r in mine if r["outcome"] == "success" and bool(r.get("release_before_grasp"))
        ),
        "episodes_with_body_contact": int((body > 0).sum()),
        "episodes_sim_unstable": sum(1 for r in mine if _value(r, "sim_unstable") > 0),
        "successes_sim_unstable": sum(
            1 for r in mine if r["outcome"] == "success" and _value(r, "sim_unstable") > 0
        ),
    }
    for name, vals in (("body_contact_force", body), ("peak_contact_force", peak)):
        for q, v in zip(("q50", "q90", "q99", "max"), quantiles(vals), strict=True):
            row[f"{name}_{q}"] = v
    return row
