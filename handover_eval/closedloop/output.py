"""Output files and console summaries of the ``closed-loop`` and ``theta-sweep`` commands.

closed-loop writes ``closed_loop.md/.csv/.png`` and ``closed_loop_{episodes,paired,ghosts,models,
timing}.csv``; theta-sweep writes ``theta_sweep.md/.csv/.png`` and
``theta_sweep_{episodes,extremes}.csv``; presentation writes ``presentation.md/.csv/.png``. They
take the values a run returned
(:class:`.run.ClosedLoopRun`, :class:`.theta_sweep.SweepRun`) and start no computation beyond
the tables of :mod:`.report` and :mod:`.theta_sweep`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

from handover_eval.closedloop.models import ModelRecord
from handover_eval.closedloop.run import ClosedLoopEvalConfig, ClosedLoopRun
from handover_eval.receivers import SETS
from handover_eval.reporting import markdown_table, write_csv, write_png, write_text
from handover_eval.roster import label

if TYPE_CHECKING:
    from handover_eval.closedloop.theta_sweep import SweepConfig, SweepRun


def timing_rows(rows: list[dict]) -> list[dict]:
    """Per agent and set: episodes, env steps and the worker wall time they took."""
    out = []
    for key in dict.fromkeys((r["agent"], r["set"]) for r in rows):
        mine = [r for r in rows if (r["agent"], r["set"]) == key]
        wall, steps = sum(r["wall_s"] for r in mine), sum(r["steps"] for r in mine)
        out.append(
            {
                "agent": key[0],
                "set": key[1],
                "episodes": len(mine),
                "steps": steps,
                "worker_s": wall,
                "s_per_episode": wall / len(mine),
                "ms_per_step": 1e3 * wall / max(1, steps),
            }
        )
    return out


def _models_text(models: list[ModelRecord]) -> str:
    if not models:
        return "No learning agents."
    rows = {}
    for m in models:
        rows.setdefault((m.agent, m.how), []).append(m)
    body = [
        [
            label(a),
            how,
            len(ms),
            ", ".join(str(f) for f in sorted({m.fold for m in ms})),
            f"{sum(m.seconds for m in ms):.1f}",
        ]
        for (a, how), ms in rows.items()
    ]
    return markdown_table(["agent", "model", "count", "folds", "seconds (sum)"], body)


def _person(settings: tuple[str, ...]) -> str:
    """The person of a run, as its header names it."""
    if not settings:
        return "the default person"
    return "person switches " + ", ".join(f"`{s}`" for s in settings) + " (docs/simulator.md)"


def _header(title: str, dataset, receivers: ClosedLoopEvalConfig, quick: bool, n_rec: str) -> str:
    th = receivers.params
    return (
        f"# {title}\n\nDataset: {dataset.name} ({len(dataset)} episodes). Receivers: {n_rec}. "
        f"Θ = K {th.stiffness:g} N/m, B {th.damping:g} N·s/m, t_f {th.forecast_time:g} s, f_r "
        f"{th.release_force:g} N. Learning agents: Table I's {receivers.folds}-fold split (seed "
        f"{receivers.seed}); a replay of fold f meets the model trained on the other folds, the "
        f"scripted walkers meet the fold-{receivers.walker_fold} model. Replays: hand mode "
        f"`{receivers.hand_mode}`. Sensing profile `{receivers.sensing}` (docs/sensing.md). "
        f"Person: {_person(receivers.person)}."
        f"{' **Quick run: tiny models, never for reported numbers.**' if quick else ''}\n"
    )


def write_closed_loop(
    run: ClosedLoopRun,
    cfg: ClosedLoopEvalConfig,
    dataset,
    out: Path,
    n_boot: int,
    seed: int,
    quick: bool,
) -> None:
    """Write the closed-loop tables, Markdown and plot of ``run`` into ``out``; print a summary.

    ``n_boot`` resamples (seeded by ``seed``) give the paired comparisons' CIs; ``quick`` marks
    the Markdown as a quick run.
    """
    from handover_eval.closedloop import markdown as md
    from handover_eval.closedloop import report as rep
    from handover_eval.closedloop.plot import closed_loop_figure

    agg = rep.aggregate(run.rows)
    pairs = (
        rep.paired(run.rows, reference=cfg.reference, n_boot=n_boot, seed=seed)
        if cfg.reference in cfg.agents
        else []
    )
    ghost = rep.ghosts(run.rows)
    timing = timing_rows(run.rows)
    n_sets = {s: sum(1 for r in run.receivers if r.set == s) for s in SETS}
    n_ood = sum(1 for r in run.receivers if r.set == "replay" and r.is_ood)
    n_rec = (
        f"{n_sets['id']} ID + {n_sets['ood']} OOD scripted walkers, {n_sets['replay']} replays "
        f"({n_sets['replay'] - n_ood} ID + {n_ood} OOD) of folds {list(run.replay_folds)}"
    )
    worker_s = sum(t["worker_s"] for t in timing)
    footer = (
        "## Models and timing\n\n"
        + _models_text(run.models)
        + "\nModel preparation (training or checking Table I's checkpoints): "
        f"{run.prepare_seconds:.1f} s. Episodes: {len(run.rows)} in {run.episode_seconds:.1f} s "
        f"wall time with {cfg.workers} worker(s) ({worker_s:.1f} s of episode time in the "
        "workers; per agent and set: `closed_loop_timing.csv`).\n"
    )
    write_csv(run.rows, out / "closed_loop_episodes.csv")
    write_csv(agg, out / "closed_loop.csv")
    write_csv(pairs, out / "closed_loop_paired.csv")
    write_csv(ghost, out / "closed_loop_ghosts.csv")
    write_csv([dataclasses.asdict(m) for m in run.models], out / "closed_loop_models.csv")
    write_csv(timing, out / "closed_loop_timing.csv")
    write_text(
        md.markdown(
            agg, pairs, ghost, _header("Closed-loop evaluation", dataset, cfg, quick, n_rec),
            footer, reference=cfg.reference,
        ),
        out / "closed_loop.md",
    )
    write_png(
        closed_loop_figure(
            run.rows,
            agg,
            f"Closed loop with the simulated person ({n_rec}); Θ = {cfg.params.as_array()}",
        ),
        out / "closed_loop.png",
    )
    print(
        "\n"
        + markdown_table(
            [
                "agent",
                "set",
                "n",
                "success [95 % CI]",
                "other outcomes",
                "handover time (s)",
                "time lost (s)",
            ],
            [
                [
                    label(r["agent"]),
                    r["set"],
                    r["n"],
                    md.success_cell(r),
                    md.outcomes_cell(r),
                    md.med_iqr(r, "handover_time", 2),
                    md.med_iqr(r, "time_lost", 2),
                ]
                for r in agg
            ],
        )
    )
    g = ghost[0]
    print(
        f"no ghosts: max penetration {1000 * g['max_penetration_m']:.1f} mm, successes released "
        f"before the grasp {g['successes_release_before_grasp']}, peak body contact q50/q99/max "
        + "/".join(f"{g[f'body_contact_force_{q}']:.0f}" for q in ("q50", "q99", "max"))
        + " N"
    )
    trained = sum(m.seconds for m in run.models if m.how == "trained")
    print(
        f"models: {run.prepare_seconds:.0f} s preparing ({trained:.0f} s training); episodes: "
        f"{len(run.rows)} in {run.episode_seconds:.0f} s with {cfg.workers} worker(s)"
    )


def write_theta_sweep(
    run: SweepRun, sweep: SweepConfig, dataset, out: Path, n_boot: int, seed: int, quick: bool
) -> None:
    """Write the Θ sweep's tables, Markdown and plot of ``run`` into ``out``; print the verdicts.

    ``n_boot`` resamples (seeded by ``seed``) give the CIs; ``quick`` marks the Markdown.
    """
    from handover_eval.closedloop import theta_sweep as ts
    from handover_eval.closedloop.report import is_ood

    rows, models, seconds = run.rows, run.models, run.seconds
    per_value, extremes = ts.summarise(rows, n_boot, seed)
    cfg = sweep.receivers
    n_sets = {s: len({r["receiver"] for r in rows if r["set"] == s}) for s in SETS}
    n_ood = len({r["receiver"] for r in rows if r["set"] == "replay" and is_ood(r)})
    n_rec = (
        f"{n_sets['id']} ID + {n_sets['ood']} OOD scripted walkers"
        + (
            f", {n_sets['replay']} replays ({n_sets['replay'] - n_ood} ID + {n_ood} OOD)"
            if n_sets["replay"]
            else ""
        )
        + ", the same at every value"
    )
    header = _header(
        f"Θ sweep: {label(sweep.agent)}", dataset, cfg, quick, n_rec
    ).replace("Θ = K", "Base Θ (the others while one is swept) = K")
    footer = (
        f"\n## Models and timing\n\n{_models_text(models)}\n{len(rows)} episodes in "
        f"{seconds:.1f} s with {cfg.workers} worker(s). Results come from the simulated person.\n"
    )
    write_csv(rows, out / "theta_sweep_episodes.csv")
    write_csv(per_value, out / "theta_sweep.csv")
    write_csv(extremes, out / "theta_sweep_extremes.csv")
    write_text(ts.markdown(per_value, extremes, header, footer), out / "theta_sweep.md")
    write_png(
        ts.sweep_figure(per_value, f"Θ sweep, {sweep.agent}, {n_rec} (simulated person)"),
        out / "theta_sweep.png",
    )
    print(
        "\n"
        + markdown_table(
            ["parameter", "set", "moves", "outcomes (high - low end, 95 % CI excludes 0)"],
            [
                [ts.SYMBOLS[v["param"]], v["set"], "yes" if v["moves"] else "no",
                 v["outcomes_moved"] or "-"]
                for v in ts.verdicts(extremes)
            ],
        )
    )


def write_presentation(rows: list[dict], ranges: dict, table: list[dict], out_dir: Path,
                       source: str = "") -> list[Path]:
    """``presentation.md``, ``.csv`` and ``.png`` (:mod:`.presentation`) into ``out_dir``."""
    from handover_eval.closedloop.presentation import figure, markdown

    out_dir.mkdir(parents=True, exist_ok=True)
    return [write_text(markdown(table, ranges, source), out_dir / "presentation.md"),
            write_csv(table, out_dir / "presentation.csv"),
            write_png(figure(rows, ranges), out_dir / "presentation.png", dpi=110)]
