"""The one writer of each result format (CSV, text/Markdown, PNG), each atomic, and the CSV reader.

Every file is written to a temporary name beside it and renamed over ``path``, so a killed run
leaves the previous file or the new one, never half of one."""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

# The paper's Table I (RMS error in mm, mean +- std over a stratified 10-fold split, full public
# set).
PAPER_TABLE1: dict[str, dict[str, tuple[float, float]]] = {
    "bc_mlp": {"id": (152.27, 289.11), "ood": (166.50, 311.60)},
    "act": {"id": (67.57, 5.06), "ood": (71.04, 7.14)},
    "iaal": {"id": (55.10, 2.28), "ood": (61.82, 4.82)},
    "ours": {"id": (55.13, 2.48), "ood": (61.83, 5.32)},
}

METHOD_LABELS: dict[str, str] = {
    "bc_mlp": "BC-MLP",
    "act": "ACT",
    "iaal": "IAAL",
    "ours": "Ours (SPGP)",
    "cv": "Constant velocity",
}


def mean_std(mean: float, std: float, digits: int = 2) -> str:
    """'55.13 ± 2.48', or 'n/a' when the mean is missing or not finite."""
    if mean is None or not math.isfinite(float(mean)):
        return "n/a"
    if std is None or not math.isfinite(float(std)):
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def write_csv(rows: Sequence[Mapping[str, object]], path: str | os.PathLike) -> Path:
    """Write dict rows to CSV (columns in first-seen order); atomically replaces ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    columns: list[str] = []
    for row in rows:
        columns.extend(k for k in row if k not in columns)
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt_cell(v) for k, v in row.items()})
    os.replace(tmp, path)
    return path


def read_csv(path: str | os.PathLike) -> list[dict[str, str]]:
    """Rows of a CSV written by :func:`write_csv` (values as strings)."""
    with Path(path).open(newline="") as fh:
        return list(csv.DictReader(fh))


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """A GitHub-flavoured Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def write_text(text: str, path: str | os.PathLike) -> Path:
    """Write ``text`` to ``path`` atomically, creating parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


def write_png(fig: Any, path: str | os.PathLike, dpi: float | None = None) -> Path:
    """Save the matplotlib figure ``fig`` as a PNG at ``path`` atomically, then close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    try:
        fig.savefig(tmp, format="png", **({} if dpi is None else {"dpi": dpi}))
        os.replace(tmp, path)
    finally:
        plt.close(fig)
    return path


def _fmt_cell(value: object) -> object:
    if isinstance(value, float):
        return f"{value:.6g}"
    return value
