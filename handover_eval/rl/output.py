"""The files of an RL run beside its checkpoint: ``train_log.csv`` (the learning curve),
``learning_curve.png`` and ``train_summary.json``, rewritten (atomically) after every checkpoint
from the training state, which the checkpoint holds."""

from __future__ import annotations

import json
from pathlib import Path

from baselines.rl.config import RLConfig
from handover_eval.reporting import write_csv, write_png, write_text
from handover_eval.rl.report import curve_figure

CURVE_CSV = "train_log.csv"
CURVE_PNG = "learning_curve.png"
SUMMARY = "train_summary.json"


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
    write_text(json.dumps(body, indent=1, default=str), out / SUMMARY)
