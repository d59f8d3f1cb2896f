"""``evaluate.py theta-sweep``: does each of Θ = K, B, t_f, f_r change the handover?

Each parameter is swept across the paper's CoSpar range (``handover_env.config.THETA_RANGES``,
``values`` evenly spaced points) with the others at Θ̂, for one agent on the same receivers at
every value (seeded scripted ID and OOD walkers, optionally replays). Per value and outcome: the
success rate (mean) or the median over receivers, with a bootstrap CI over receivers (the
run-to-run noise: which receivers one happens to meet). Per parameter: the paired difference
between the two extreme values on the same receivers, with its bootstrap CI; the parameter
*moves* an outcome when that CI excludes 0. Everything is given over all receivers (set ``all``)
and per receiver group of :data:`handover_eval.closedloop.report.GROUPS` (scripted ID / OOD
walkers, replayed ID / OOD recordings, all replays), so that OOD receivers are never hidden in a
pooled number.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from handover_env.config import THETA_RANGES, HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.closedloop.models import ModelRecord, prepare_models
from handover_eval.closedloop.report import EFFORT, GROUPS, groups_of, paired_metrics
from handover_eval.closedloop.run import (
    ClosedLoopEvalConfig,
    build_receivers,
    plan_jobs,
    run_jobs,
)
from handover_eval.closedloop.stats import N_BOOTSTRAP, bootstrap_ci, stable_seed
from handover_eval.methods import MethodOptions
from handover_eval.reporting import markdown_table

PARAMS = tuple(THETA_RANGES)
SYMBOLS = {
    "stiffness": "K (N/m)",
    "damping": "B (N·s/m)",
    "forecast_time": "t_f (s)",
    "release_force": "f_r (N)",
}
#: metric -> (row column, statistic, digits).
METRICS: dict[str, tuple[str, str, int]] = {
    "success": ("is_success", "mean", 2),
    "handover_time": ("handover_time", "median", 2),
    "transfer_time": ("transfer_time", "median", 2),
    "hold_time": ("hold_time", "median", 3),
    "release_force": ("release_force", "median", 1),
    "pull_force": ("pull_force", "median", 1),
    "peak_contact_force": ("peak_contact_force", "median", 1),
    "body_contact_force": ("body_contact_force", "median", 1),
    **{m: (m, "median", 3 if m == "path_deviation" else 2) for m in EFFORT if m != "pull_force"},
    "robot_jerk_rms": ("robot_jerk_rms", "median", 0),
}
GROUP_COLOURS = {
    "all": "k",
    "walker-id": "tab:blue",
    "walker-ood": "tab:orange",
    "replay-id": "tab:green",
    "replay-ood": "tab:red",
}
PLOTTED = (
    "success",
    "handover_time",
    "release_force",
    "pull_force",
    "peak_contact_force",
    "time_lost",
    "arm_extended_time",
    "robot_jerk_rms",
)


@dataclass(frozen=True)
class SweepConfig:
    """What ``evaluate.py theta-sweep`` runs.

    Args:
        agent: the agent (default the planner ``ours``; ``reactive`` is the model-free check).
        params: which of K, B, t_f, f_r to sweep (``THETA_RANGES`` names).
        values: points per parameter, evenly spaced over its range (the ends included).
        walkers: scripted walkers per set (ID, OOD), the same at every value.
        replays_per_fold: replays of each held-out fold to add (0: walkers only).
        receivers: the :class:`ClosedLoopEvalConfig` that picks the receivers (folds, hand mode,
            ...).
    """

    agent: str = "ours"
    params: tuple[str, ...] = PARAMS
    values: int = 5
    walkers: int = 20
    replays_per_fold: int = 0
    receivers: ClosedLoopEvalConfig = dataclasses.field(default_factory=ClosedLoopEvalConfig)

    def __post_init__(self) -> None:
        (agent,) = roster.check_agents([self.agent])
        object.__setattr__(self, "agent", agent)
        if roster.entry(agent).replays_only and not self.replays_per_fold:
            raise ValueError(f"{agent} needs replays: --replays-per-fold N")
        bad = [p for p in self.params if p not in PARAMS]
        if bad or not self.params:
            raise ValueError(f"unknown Θ parameter(s) {bad}; choose from {list(PARAMS)}")
        if self.values < 2:
            raise ValueError(
                f"--values must be >= 2 (the extremes are compared), got {self.values}"
            )
        if self.walkers < 0 or self.replays_per_fold < 0:
            raise ValueError("--walkers and --replays-per-fold must be >= 0")


def grid(param: str, n: int, base: HandoverParams) -> list[HandoverParams]:
    """``n`` Θ with ``param`` evenly spaced over its paper range, the others as in ``base``."""
    lo, hi = THETA_RANGES[param]
    return [dataclasses.replace(base, **{param: float(v)}) for v in np.linspace(lo, hi, n)]


@dataclass
class SweepRun:
    """What :func:`run_sweep` returns: the episode rows (with ``param`` and ``value``), the fold
    models' records and the wall seconds of the episodes."""

    rows: list[dict]
    models: list[ModelRecord]
    seconds: float


def run_sweep(
    config: SweepConfig,
    dataset: HandoverDataset,
    data: str | None,
    options: MethodOptions,
    cache_dir: Path,
    progress: bool = True,
) -> SweepRun:
    """Every (parameter, value) on the same receivers: rows, model records, episode seconds."""
    sets = ("id", "ood") + (("replay",) if config.replays_per_fold else ())
    base = dataclasses.replace(
        config.receivers,
        agents=(config.agent,),
        sets=sets,
        walkers=config.walkers,
        replays_per_fold=config.replays_per_fold or None,
    )
    specs, _ = build_receivers(base, dataset, data)
    splits = dataset.stratified_kfold(base.folds, base.seed)
    needed = sorted({base.walker_fold} | {s.fold for s in specs if s.fold is not None})
    models = prepare_models(dataset, [config.agent], splits, needed, options, cache_dir, progress)
    token = f"{os.getpid()}-{uuid.uuid4().hex}"
    jobs = []
    for param in config.params:
        for theta in grid(param, config.values, base.params):
            cfg = dataclasses.replace(base, params=theta)
            extra = (("param", param), ("value", float(getattr(theta, param))))
            jobs += [
                dataclasses.replace(j, extra=extra)
                for j in plan_jobs(cfg, specs, splits, options, cache_dir, token)
            ]
    t0 = time.perf_counter()
    rows, fits = run_jobs(dataset, jobs, base.workers, progress, desc="theta-sweep")
    return SweepRun(rows, models + fits, time.perf_counter() - t0)


def _col(rows: Sequence[dict], column: str) -> np.ndarray:
    return np.array(
        [float(r[column]) if r[column] is not None else math.nan for r in rows], dtype=float
    )


def sweep_groups(rows: Sequence[dict]) -> list[str]:
    """``all`` and the receiver groups present in ``rows``, in table order."""
    return ["all", *(g for g in GROUPS if any(g in groups_of(r) for r in rows))]


def summarise(
    rows: Sequence[dict], n_boot: int = N_BOOTSTRAP, seed: int = 0
) -> tuple[list[dict], list[dict]]:
    """``(per-value rows, per-parameter extreme comparisons)``, per receiver group (module
    docstring)."""
    per_value, extremes = [], []
    for param in dict.fromkeys(r["param"] for r in rows):
        for group in sweep_groups(rows):
            mine = [
                r for r in rows
                if r["param"] == param and (group == "all" or group in groups_of(r))
            ]
            if mine:
                _summarise_one(mine, param, group, n_boot, seed, per_value, extremes)
    return per_value, extremes


def _summarise_one(
    mine: list[dict],
    param: str,
    group: str,
    n_boot: int,
    seed: int,
    per_value: list[dict],
    extremes: list[dict],
) -> None:
    """:func:`summarise` of one parameter and receiver group, appended to the two lists."""
    values = sorted({r["value"] for r in mine})
    for v in values:
        at = [r for r in mine if r["value"] == v]
        for metric, (column, stat, _) in METRICS.items():
            vals = _col(at, column)
            est, lo, hi = bootstrap_ci(
                vals, stat, n_boot, stable_seed(param, group, v, metric, base=seed)
            )
            per_value.append(
                {
                    "param": param,
                    "set": group,
                    "value": v,
                    "metric": metric,
                    "stat": stat,
                    "n": int(np.isfinite(vals).sum()),
                    "estimate": est,
                    "low": lo,
                    "high": hi,
                }
            )
    lo_rows = [r for r in mine if r["value"] == values[0]]
    hi_rows = [r for r in mine if r["value"] == values[-1]]
    metrics = {m: (c, s) for m, (c, s, _) in METRICS.items()}
    extremes += paired_metrics(
        hi_rows,
        lo_rows,
        {"param": param, "set": group, "low_value": values[0], "high_value": values[-1]},
        n_boot,
        seed,
        metrics,
    )


def _moved(e: dict) -> str:
    """'pull_force +0.158 (+0.6 %) [+0.051, +0.235]': a difference, relative to the low end."""
    if e["metric"] == "success":
        return (
            f"success {100 * e['diff']:+.0f} pp [{100 * e['diff_low']:+.0f}, "
            f"{100 * e['diff_high']:+.0f}]"
        )
    ref = e["reference_value"]
    # relative only to a reference that is not zero up to rounding (a summed 0 s is ~1e-17 s)
    rel = (
        f" ({100 * e['diff'] / abs(ref):+.1f} %)" if math.isfinite(ref) and abs(ref) > 1e-9 else ""
    )
    return f"{e['metric']} {e['diff']:+.3g}{rel} [{e['diff_low']:+.3g}, {e['diff_high']:+.3g}]"


def verdicts(extremes: Sequence[dict]) -> list[dict]:
    """Per parameter and receiver set: whether some outcome moves beyond its noise, and which."""
    out = []
    for param, group in dict.fromkeys((e["param"], e.get("set", "all")) for e in extremes):
        moved = [
            e for e in extremes
            if e["param"] == param and e.get("set", "all") == group and e["ci_excludes_zero"]
        ]
        out.append(
            {
                "param": param,
                "set": group,
                "moves": bool(moved),
                "outcomes_moved": "; ".join(_moved(e) for e in moved),
            }
        )
    return out


def markdown(per_value: list[dict], extremes: list[dict], header: str, footer: str = "") -> str:
    """theta_sweep.md: the verdicts, then one table per parameter (values x outcomes)."""
    text = header + "\n## Does each parameter move an outcome beyond its noise?\n\n"
    text += markdown_table(
        [
            "parameter",
            "set",
            "moves an outcome",
            "outcomes whose extreme-value paired CI excludes 0",
        ],
        [
            [SYMBOLS[v["param"]], v["set"], "yes" if v["moves"] else "no",
             v["outcomes_moved"] or "–"]
            for v in verdicts(extremes)
        ],
    )
    text += (
        "\nPaired difference (high end - low end of the range) on the same receivers: success as a "
        "difference in rate, the others as the median paired difference; [95 % bootstrap CI]. "
        "Set `all`: every receiver; `walker-id` / `walker-ood`: the scripted walkers; "
        "`replay-id` / `replay-ood` / `replay-all`: the replayed recordings by `is_ood`.\n"
    )
    shown = [m for m in METRICS if m not in ("transfer_time",)]
    for param in dict.fromkeys(r["param"] for r in per_value):
        by = {
            (r.get("set", "all"), r["value"], r["metric"]): r
            for r in per_value
            if r["param"] == param
        }
        keys = list(dict.fromkeys((g, v) for g, v, _ in by))
        body = []
        for g, v in keys:
            cells = []
            for m in shown:
                r, d = by[(g, v, m)], METRICS[m][2]
                scale = 100 if m == "success" else 1
                cells.append(
                    "–"
                    if not math.isfinite(r["estimate"])
                    else f"{scale * r['estimate']:.{0 if m == 'success' else d}f} "
                    f"[{scale * r['low']:.{0 if m == 'success' else d}f}, "
                    f"{scale * r['high']:.{0 if m == 'success' else d}f}]"
                )
            body.append([g, f"{v:g}", *cells])
        text += f"\n### {SYMBOLS[param]}\n\n" + markdown_table(
            [
                "set",
                SYMBOLS[param],
                *[("success %" if m == "success" else m.replace("_", " ")) for m in shown],
            ],
            body,
        )
    return (
        text
        + (
            "\nPer value: success rate or median over the receivers, [95 % bootstrap CI over "
            "receivers]. Handover time over successes; release force where a release happened; "
            "the rest over all episodes.\n"
        )
        + footer
    )


def sweep_figure(per_value: list[dict], title: str) -> Any:
    """One row of panels per parameter; each panel one outcome against the value, with its CI."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = list(dict.fromkeys(r["param"] for r in per_value))
    fig, axes = plt.subplots(
        len(params),
        len(PLOTTED),
        figsize=(2.3 * len(PLOTTED), 2.1 * len(params)),
        dpi=120,
        squeeze=False,
    )
    for i, param in enumerate(params):
        for j, metric in enumerate(PLOTTED):
            ax = axes[i, j]
            scale = 100 if metric == "success" else 1
            for group in dict.fromkeys(r.get("set", "all") for r in per_value):
                rs = sorted(
                    (
                        r for r in per_value
                        if r["param"] == param and r["metric"] == metric
                        and r.get("set", "all") == group
                    ),
                    key=lambda r: r["value"],
                )
                if not rs or group == "replay-all":  # the tables have it; two lines pool it
                    continue
                x = [r["value"] for r in rs]
                y = np.array([scale * r["estimate"] for r in rs])
                err = [y - [scale * r["low"] for r in rs], [scale * r["high"] for r in rs] - y]
                ax.errorbar(x, y, yerr=err, marker="o", ms=3, capsize=2, lw=1,
                            color=GROUP_COLOURS.get(group, "k"), label=group)
            if i == 0 and j == 0:
                ax.legend(fontsize=6)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            if i == 0:
                ax.set_title(
                    "success %" if metric == "success" else metric.replace("_", " "), fontsize=8
                )
            if j == 0:
                ax.set_ylabel(SYMBOLS[param], fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig
