"""``evaluate.py sensing-sweep``: how much of each agent's result the paper's sensors cost.

One factor at a time around the ``"paper"`` sensor profile (docs/sensing.md), every agent on the
same receivers at every point (seeded scripted ID and OOD walkers, optionally replays):

* camera latency 0, 50, 100 (paper), 150, 200, 300 ms;
* wrist F/T noise 0, 0.5x, 1x (paper), 2x the UR5e datasheet's precision (3.5 N);
* the controller's inertia: the paper's constant M (4.7 kg) or the arm's Λ(q).

Per point and agent: the success rate (Wilson CI), the median handover time over successes and
the premature-release rate; and the paired difference against the reactive agent at the same
point on the same receivers (bootstrap CI), as in the closed-loop table. Points equal to the paper
profile are one run, shared by the three factors.

The episodes run through the closed-loop machinery (:func:`.run.plan_jobs`, :func:`.run.run_jobs`,
the env made with ``sensing="paper"`` and the point's ``sensors=`` overrides); :func:`summarise`
and :func:`paired` make the tables, :func:`markdown` and :func:`sweep_figure` the report,
:func:`write_sensing_sweep` the files (sensing_sweep.md/.csv/.png, the paired and the episode
CSVs).
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

from handover_env.data.dataset import HandoverDataset
from handover_env.sensors import make_profile
from handover_eval import roster
from handover_eval.closedloop.models import ModelRecord, prepare_models
from handover_eval.closedloop.report import paired_metrics
from handover_eval.closedloop.run import ClosedLoopEvalConfig, build_receivers, plan_jobs, run_jobs
from handover_eval.closedloop.stats import N_BOOTSTRAP, wilson_interval
from handover_eval.methods import MethodOptions
from handover_eval.reporting import markdown_table, write_csv, write_png, write_text

AGENTS = ("reactive", "ours", "iaal", "bc-mlp", "act", "giver-replay")
REFERENCE = "reactive"
PAPER = make_profile("paper")
#: factor -> (label, unit, values, value -> sensors overrides).
FACTORS: dict[str, tuple[str, str, tuple[float, ...], Any]] = {
    "camera_latency": (
        "camera latency", "ms", (0.0, 50.0, 100.0, 150.0, 200.0, 300.0),
        lambda v: {"camera": {"latency": v / 1000.0}},
    ),
    "ft_noise": (
        "F/T noise (x datasheet 3.5 N)", "x", (0.0, 0.5, 1.0, 2.0),
        lambda v: {"wrist": {"precision": v * PAPER.wrist.precision}},
    ),
    "controller": (
        "controller M (0 = Λ(q))", "kg", (PAPER.controller.inertia, 0.0),
        lambda v: {"controller": {"inertia": v}},
    ),
}
#: metric -> (row column, statistic) for the paired differences against the reference agent.
PAIRED = {
    "success": ("is_success", "mean"),
    "handover_time": ("handover_time", "median"),
    "premature_release": ("premature_release", "mean"),
}


@dataclass(frozen=True)
class SensingSweepConfig:
    """What ``evaluate.py sensing-sweep`` runs.

    Args:
        agents: the agents (:data:`AGENTS` by default; the reference ``reactive`` always runs).
        factors: which of :data:`FACTORS` to sweep.
        walkers: scripted walkers per set (ID, OOD), the same at every point.
        replays_per_fold: replays of each held-out fold to add (0: walkers only; giver-replay
            needs them).
        receivers: the :class:`ClosedLoopEvalConfig` that picks the receivers and Θ.
    """

    agents: tuple[str, ...] = AGENTS
    factors: tuple[str, ...] = tuple(FACTORS)
    walkers: int = 20
    replays_per_fold: int = 0
    receivers: ClosedLoopEvalConfig = dataclasses.field(default_factory=ClosedLoopEvalConfig)

    def __post_init__(self) -> None:
        agents = roster.check_agents(list(dict.fromkeys([REFERENCE, *self.agents])))
        object.__setattr__(self, "agents", tuple(agents))
        bad = [f for f in self.factors if f not in FACTORS]
        if bad or not self.factors:
            raise ValueError(f"unknown factor(s) {bad}; choose from {list(FACTORS)}")
        if self.walkers < 0 or self.replays_per_fold < 0:
            raise ValueError("--walkers and --replays-per-fold must be >= 0")


def points(factors: Sequence[str]) -> list[tuple[str, float, dict]]:
    """``(factor, value, sensors overrides)`` of every point; the paper profile's value of each
    factor has the empty override (one shared run)."""
    out = []
    for f in factors:
        _, _, values, overrides = FACTORS[f]
        for v in values:
            ov = overrides(v)
            same = make_profile("paper", ov) == PAPER
            out.append((f, float(v), {} if same else ov))
    return out


@dataclass
class SensingSweepRun:
    """What :func:`run_sensing_sweep` returns: rows (with ``factor``, ``value``), models,
    the episodes' wall seconds."""

    rows: list[dict]
    models: list[ModelRecord]
    seconds: float


def run_sensing_sweep(
    config: SensingSweepConfig,
    dataset: HandoverDataset,
    data: str | None,
    options: MethodOptions,
    cache_dir: Path,
    progress: bool = True,
) -> SensingSweepRun:
    """Every point's episodes for every agent, on the same receivers (module docstring)."""
    sets = ("id", "ood") + (("replay",) if config.replays_per_fold else ())
    base = dataclasses.replace(
        config.receivers, agents=config.agents, sets=sets, walkers=config.walkers,
        replays_per_fold=config.replays_per_fold or None,
    )
    specs, _ = build_receivers(base, dataset, data)
    splits = dataset.stratified_kfold(base.folds, base.seed)
    needed = sorted({base.walker_fold} | {s.fold for s in specs if s.fold is not None})
    models = prepare_models(dataset, list(config.agents), splits, needed, options, cache_dir,
                            progress)
    token = f"{os.getpid()}-{uuid.uuid4().hex}"
    planned = plan_jobs(base, specs, splits, options, cache_dir, token)
    runs: dict[str, list] = {}  # env kwargs -> its jobs (a shared paper run)
    tags: dict[str, list[tuple[str, float]]] = {}
    for factor, value, ov in points(config.factors):
        kwargs = dataclasses.replace(base, sensing="paper").env_kwargs(sensors=ov)
        tags.setdefault(kwargs, []).append((factor, value))
        if kwargs not in runs:
            runs[kwargs] = [dataclasses.replace(j, env_kwargs=kwargs) for j in planned]
    jobs = [j for js in runs.values() for j in js]
    t0 = time.perf_counter()
    rows, fits = run_jobs(dataset, jobs, base.workers, progress, desc="sensing-sweep")
    # run_jobs keeps the job order: the rows of one env's jobs are contiguous
    by_kwargs: dict[str, list[dict]] = {}
    k = 0
    for kwargs, js in runs.items():
        n = sum(len(j.receivers) for j in js)
        by_kwargs[kwargs] = rows[k:k + n]
        k += n
    tagged = []
    for kwargs, rs in by_kwargs.items():
        for factor, value in tags[kwargs]:
            for r in rs:
                tagged.append({"factor": factor, "value": value,
                               "premature_release": float(r["outcome"] == "premature_release"),
                               **r})
    return SensingSweepRun(tagged, models + fits, time.perf_counter() - t0)


def _col(rows: Sequence[dict], column: str) -> np.ndarray:
    return np.array(
        [float(r[column]) if r.get(column) is not None else math.nan for r in rows], dtype=float
    )


def summarise(rows: Sequence[dict]) -> list[dict]:
    """Per (factor, value, agent): n, success rate with its Wilson CI, median handover time
    (successes), premature-release rate with its Wilson CI."""
    out = []
    order = {f: i for i, f in enumerate(FACTORS)}
    agents = {a: i for i, a in enumerate(dict.fromkeys(r["agent"] for r in rows))}
    keys = sorted(dict.fromkeys((r["factor"], r["value"], r["agent"]) for r in rows),
                  key=lambda k: (order[k[0]], k[1], agents[k[2]]))
    for factor, value, agent in keys:
        at = [r for r in rows if (r["factor"], r["value"], r["agent"]) == (factor, value, agent)]
        n = len(at)
        k_ok = int(sum(bool(r["is_success"]) for r in at))
        k_pre = int(sum(r["premature_release"] for r in at))
        times = _col(at, "handover_time")
        times = times[np.isfinite(times)]
        ok_lo, ok_hi = wilson_interval(k_ok, n)
        pre_lo, pre_hi = wilson_interval(k_pre, n)
        out.append({
            "factor": factor, "value": value, "agent": agent, "n": n,
            "success": k_ok / n if n else math.nan, "success_low": ok_lo, "success_high": ok_hi,
            "handover_time": float(np.median(times)) if times.size else math.nan,
            "premature_release": k_pre / n if n else math.nan,
            "premature_low": pre_lo, "premature_high": pre_hi,
        })
    return out


def paired(rows: Sequence[dict], n_boot: int = N_BOOTSTRAP, seed: int = 0) -> list[dict]:
    """Per (factor, value, agent != reactive): paired differences agent - reactive on the same
    receivers at that point (:func:`.report.paired_metrics`)."""
    out = []
    keys = dict.fromkeys((r["factor"], r["value"], r["agent"]) for r in rows)
    for factor, value, agent in keys:
        if agent == REFERENCE:
            continue
        mine = [r for r in rows if (r["factor"], r["value"], r["agent"]) == (factor, value, agent)]
        ref = [r for r in rows
               if (r["factor"], r["value"], r["agent"]) == (factor, value, REFERENCE)]
        out += paired_metrics(mine, ref, {"factor": factor, "value": value, "agent": agent},
                              n_boot, seed, PAIRED)
    return out


def _pct(x: float, lo: float, hi: float) -> str:
    return "–" if not math.isfinite(x) else f"{100 * x:.0f} [{100 * lo:.0f}, {100 * hi:.0f}]"


def _diff(p: dict | None) -> str:
    if p is None or not math.isfinite(p["diff"]):
        return "–"
    scale, d = (100.0, 0) if p["stat"] == "mean" else (1.0, 2)
    return (f"{scale * p['diff']:+.{d}f} [{scale * p['diff_low']:+.{d}f}, "
            f"{scale * p['diff_high']:+.{d}f}]")


def markdown(summary: list[dict], pairs: list[dict], header: str, footer: str = "") -> str:
    """sensing_sweep.md: one table per factor, rows (value, agent)."""
    pd = {(p["factor"], p["value"], p["agent"], p["metric"]): p for p in pairs}
    text = header
    for factor in dict.fromkeys(s["factor"] for s in summary):
        label, unit, _, _ = FACTORS[factor]
        body = []
        for s in (s for s in summary if s["factor"] == factor):
            key = (factor, s["value"], s["agent"])
            paper = make_profile("paper", FACTORS[factor][3](s["value"])) == PAPER
            body.append([
                f"{s['value']:g}{' (paper)' if paper else ''}", s["agent"], str(s["n"]),
                _pct(s["success"], s["success_low"], s["success_high"]),
                "–" if not math.isfinite(s["handover_time"]) else f"{s['handover_time']:.2f}",
                _pct(s["premature_release"], s["premature_low"], s["premature_high"]),
                _diff(pd.get((*key, "success"))), _diff(pd.get((*key, "handover_time"))),
                _diff(pd.get((*key, "premature_release"))),
            ])
        text += f"\n## {label} ({unit})\n\n" + markdown_table(
            [label, "agent", "n", "success % [95 % CI]", "handover time s (median)",
             "premature release % [CI]", "Δ success pp vs reactive", "Δ time s vs reactive",
             "Δ premature pp vs reactive"],
            body,
        )
    return text + (
        "\nOne factor at a time, the others at the paper profile (docs/sensing.md). Success and "
        "premature release: rate over the receivers, Wilson 95 % CI; handover time: median over "
        "successes. Δ: paired difference agent - reactive on the same receivers at the same point "
        "(rates: mean, in percentage points; time: median), [95 % bootstrap CI].\n"
    ) + footer


def sweep_figure(summary: list[dict], title: str) -> Any:
    """One row per factor; panels success, premature release and handover time, one line per
    agent."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    factors = list(dict.fromkeys(s["factor"] for s in summary))
    metrics = (("success", 100.0, "success %"), ("premature_release", 100.0, "premature %"),
               ("handover_time", 1.0, "handover time s"))
    fig, axes = plt.subplots(len(factors), 3, figsize=(10, 2.6 * len(factors)), dpi=120,
                             squeeze=False)
    for i, factor in enumerate(factors):
        for j, (m, scale, name) in enumerate(metrics):
            ax = axes[i, j]
            for agent in dict.fromkeys(s["agent"] for s in summary):
                rs = sorted((s for s in summary if s["factor"] == factor and s["agent"] == agent),
                            key=lambda s: s["value"])
                ax.plot([s["value"] for s in rs], [scale * s[m] for s in rs], marker="o", ms=3,
                        lw=1, label=agent)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            ax.set_xlabel(f"{FACTORS[factor][0]} ({FACTORS[factor][1]})", fontsize=7)
            if i == 0:
                ax.set_title(name, fontsize=8)
    axes[0, 0].legend(fontsize=6)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def write_sensing_sweep(run: SensingSweepRun, config: SensingSweepConfig, dataset, out: Path,
                        n_boot: int, seed: int, quick: bool) -> None:
    """Write sensing_sweep.md/.csv/.png, sensing_sweep_paired.csv and the episodes into ``out``."""
    summary = summarise(run.rows)
    pairs = paired(run.rows, n_boot, seed)
    n_id = len({r["receiver"] for r in run.rows if r["set"] == "id"})
    n_ood = len({r["receiver"] for r in run.rows if r["set"] == "ood"})
    n_rep = len({r["receiver"] for r in run.rows if r["set"] == "replay"})
    rec = f"{n_id} ID + {n_ood} OOD walkers" + (f", {n_rep} replays" if n_rep else "")
    theta = config.receivers.params.as_array()
    note = " (--quick: not for reporting)" if quick else ""
    header = (
        f"# Sensing sweep: what the paper's sensors cost{note}\n\n"
        f"Dataset {dataset.name}; {rec}, the same at every point; Θ = {list(theta)}; agents "
        f"{', '.join(config.agents)}.\n"
    )
    footer = f"\n{len(run.rows)} episode rows in {run.seconds:.1f} s. Simulated person.\n"
    write_csv(run.rows, out / "sensing_sweep_episodes.csv")
    write_csv(summary, out / "sensing_sweep.csv")
    write_csv(pairs, out / "sensing_sweep_paired.csv")
    write_text(markdown(summary, pairs, header, footer), out / "sensing_sweep.md")
    write_png(sweep_figure(summary, f"Sensing sweep ({rec}, simulated person)"),
              out / "sensing_sweep.png")
