"""The files of the open-loop experiments: each takes an :class:`.experiments.OpenLoopRun` (values)
and writes its tables and figure through the one writer of each format
(:mod:`handover_eval.reporting`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from handover_env.data.dataset import HandoverDataset
from handover_eval.openloop.experiments import OpenLoopRun
from handover_eval.openloop.protocol import OpenLoopProtocol
from handover_eval.openloop.report import sample_efficiency_figure, table1_markdown, tradeoff_figure
from handover_eval.reporting import write_csv, write_png, write_text


def write_table1(
    run: OpenLoopRun,
    dataset: HandoverDataset,
    folds: int,
    seed: int,
    protocol: OpenLoopProtocol,
    giver_state: bool,
    out: Path,
    test_data: HandoverDataset | None = None,
) -> list[Path]:
    """table1.csv, table1_folds.csv, table1_episodes.csv and table1.md in ``out`` (``test_data``:
    the ``--replay-data`` the methods were scored on)."""
    return [
        write_csv(run.rows, out / "table1.csv"),
        write_csv(run.per_fold, out / "table1_folds.csv"),
        write_csv(run.episodes, out / "table1_episodes.csv"),
        write_text(
            table1_markdown(run.rows, dataset, folds, seed, protocol, giver_state, test_data),
            out / "table1.md",
        ),
    ]


def write_sample_efficiency(run: OpenLoopRun, methods: Sequence[str], out: Path) -> list[Path]:
    """sample_efficiency.csv, sample_efficiency_folds.csv and the PNG (BC-MLP left out of the
    figure, as in the paper) in ``out``."""
    shown = [m for m in methods if m != "bc_mlp"] or list(methods)
    return [
        write_csv(run.rows, out / "sample_efficiency.csv"),
        write_csv(run.per_fold, out / "sample_efficiency_folds.csv"),
        write_png(sample_efficiency_figure(run.rows, shown), out / "sample_efficiency.png"),
    ]


def write_tradeoff(run: OpenLoopRun, out: Path) -> list[Path]:
    """tradeoff.csv and tradeoff.png in ``out``."""
    return [
        write_csv(run.rows, out / "tradeoff.csv"),
        write_png(tradeoff_figure(run.rows), out / "tradeoff.png"),
    ]
