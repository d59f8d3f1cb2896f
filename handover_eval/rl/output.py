"""The files of an RL run beside its checkpoint: ``train_log.csv`` (the learning curve),
``learning_curve.png`` and ``train_summary.json``, rewritten (atomically) after every checkpoint
from the training state, which the checkpoint holds. ``train_summary.json`` is strict JSON: a
number that is not finite (a curve point's handover time when none of its episodes succeeded)
is written as ``null``, never as ``NaN`` or ``Infinity``."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from baselines.rl.config import RLConfig
from handover_eval.reporting import write_csv, write_png, write_text
from handover_eval.rl.report import (
    ablation_figure,
    curve_figure,
    seeds_figure,
    seeds_summary,
)

CURVE_CSV = "train_log.csv"
CURVE_PNG = "learning_curve.png"
SUMMARY = "train_summary.json"
SEEDS_PNG = "learning_curves.png"
SEEDS_SUMMARY = "seeds_summary.json"


def write_curve(out: Path, state: dict, config: RLConfig) -> None:
    """``train_log.csv`` and ``learning_curve.png`` of ``state["curve"]``."""
    write_csv(state["curve"], out / CURVE_CSV)
    write_png(curve_figure(state["curve"], config), out / CURVE_PNG)


def write_summary(out: Path, state: dict, config: RLConfig, extra: dict) -> None:
    """``train_summary.json``: the curve's first and last points, steps/s, the config."""
    from dataclasses import asdict

    c = state["curve"]
    body = {"steps": state["steps"], "episodes": sum(state["episodes"]),
            "wall_time_s": state["wall_time_s"], "start": c[0], "end": c[-1],
            "config": asdict(config), **extra}
    write_text(json.dumps(finite_or_null(body), indent=1, default=str, allow_nan=False),
               out / SUMMARY)


def finite_or_null(value: Any) -> Any:
    """``value`` with every float that is not finite (NaN, ±inf) replaced by None, in dicts and
    lists at any depth."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(v) for v in value]
    return value


def write_seeds(out: Path, states: list[dict], config: RLConfig) -> None:
    """With several seeds, beside their ``seed-S`` folders: ``learning_curves.png`` (every seed
    and the IQM band) and ``seeds_summary.json`` (IQM and CI of the curve's start and end)."""
    write_png(seeds_figure(states, config), out / SEEDS_PNG)
    write_text(json.dumps(finite_or_null(seeds_summary(states)), indent=1, allow_nan=False),
               out / SEEDS_SUMMARY)


def _flat_scores(scores: Any) -> dict[str, object]:
    """An :class:`~handover_eval.rl.ablation.AgentScores` as CSV columns ``<set>_<metric>``."""
    return {f"{name}_{m}": v for name, metrics in scores.sets.items() for m, v in metrics.items()}


def _flat_row(row: Any) -> dict[str, object]:
    """An :class:`~handover_eval.rl.ablation.AblationRow` as CSV columns."""
    flat: dict[str, object] = {"configuration": row.label, "seed": row.seed,
                               "agent": row.scores.agent, "flags": row.flags}
    flat.update({f"curve_{k}_{m}": v for k, p in (("start", row.curve_start),
                                                  ("end", row.curve_end)) for m, v in p.items()})
    flat.update({"steps": row.steps, "wall_s": row.wall_s, "reference": row.reference})
    flat.update(_flat_scores(row.scores))
    for name, metrics in row.paired.items():
        for m, (d, lo, hi, _) in metrics.items():
            flat.update({f"paired_{name}_{m}": d, f"paired_{name}_{m}_low": lo,
                         f"paired_{name}_{m}_high": hi})
    return flat


def write_ablation(rows: list, references: list, summary: list[dict], out: Path,
                   curves: dict[str, list] | None = None) -> list[Path]:
    """``rl_ablation.md``, ``.csv`` (one line per reference agent and per seed) and ``.png``
    (:mod:`handover_eval.rl.ablation`) into ``out``; and per label of ``curves`` (``{label:
    [(seed, curve), ...]}``, :func:`~handover_eval.rl.ablation.read_curves`)
    ``out/<label>/learning_curves.png`` and ``seeds_summary.json``, the files a ``train.py rl
    --seeds`` run writes beside its seed folders."""
    from handover_eval.rl.report import ablation_markdown, curves_figure

    out.mkdir(parents=True, exist_ok=True)
    table = [{"configuration": s.agent, "seed": "", "agent": s.agent, **_flat_scores(s)}
             for s in references] + [_flat_row(r) for r in rows]
    keys = list(dict.fromkeys(k for t in table for k in t))
    # every float at full precision (repr), so that --table reads back the numbers written
    table = [{k: repr(v) if isinstance(v := t.get(k, ""), float) else v for k in keys}
             for t in table]
    written = [write_text(ablation_markdown(rows, references, summary), out / "rl_ablation.md"),
               write_csv(table, out / "rl_ablation.csv"),
               write_png(ablation_figure(rows), out / "rl_ablation.png", dpi=110)]
    for label, seeds in (curves or {}).items():
        title = f"{label}: seeds {', '.join(str(s) for s, _ in seeds)}, fixed training receivers"
        states = [{"curve": c} for _, c in seeds]
        written += [write_png(curves_figure([c for _, c in seeds], title,
                                            [f"seed {s}" for s, _ in seeds]),
                              out / label / SEEDS_PNG),
                    write_text(json.dumps(finite_or_null(seeds_summary(states)), indent=1,
                                          allow_nan=False), out / label / SEEDS_SUMMARY)]
    return written
