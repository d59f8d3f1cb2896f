"""The one writer of each result format (CSV, text/Markdown/JSON/HTML, PNG), each atomic, and the
CSV reader.

Every file goes through :func:`atomic_write_bytes` (:func:`handover_env.atomic_write.atomic_write`,
the project's one file writer): a fresh, unpredictably named temporary file beside ``path``,
created exclusively without following any link, flushed to disk and renamed over ``path``. So a
killed run leaves the previous file or the new one, never half of one, a link planted at any name
is never followed or truncated, and a ``path`` that is a symbolic link out of its folder (or not a
regular file) is refused with :class:`UnsafeTargetError` naming it."""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO

from handover_env.atomic_write import UnsafeTargetError, atomic_write, atomic_write_bytes

__all__ = [
    "PAPER_TABLE1", "UnsafeTargetError", "atomic_write_bytes", "markdown_table",
    "mean_std", "read_csv", "read_folder_csv", "write_csv", "write_png", "write_text",
]

# The paper's Table I (RMS error in mm, mean +- std over a stratified 10-fold split, full public
# set).
PAPER_TABLE1: dict[str, dict[str, tuple[float, float]]] = {
    "bc_mlp": {"id": (152.27, 289.11), "ood": (166.50, 311.60)},
    "act": {"id": (67.57, 5.06), "ood": (71.04, 7.14)},
    "iaal": {"id": (55.10, 2.28), "ood": (61.82, 4.82)},
    "ours": {"id": (55.13, 2.48), "ood": (61.83, 5.32)},
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
    columns: list[str] = []
    for row in rows:
        columns.extend(k for k in row if k not in columns)

    def fill(raw: BinaryIO) -> None:
        fh = io.TextIOWrapper(raw, encoding="utf-8", newline="")
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt_cell(v) for k, v in row.items()})
        fh.flush()
        fh.detach()  # the raw file stays open for atomic_write to sync and close

    return atomic_write(path, fill)


def read_csv(path: str | os.PathLike) -> list[dict[str, str]]:
    """Rows of a CSV written by :func:`write_csv` (values as strings)."""
    with Path(path).open(newline="") as fh:
        return list(csv.DictReader(fh))


def read_folder_csv(folder: str | os.PathLike, name: str, limit: int, columns: Sequence[str],
                    error: type[Exception], inside: str = "folder",
                    missing_hint: str = "") -> list[dict[str, str]]:
    """The rows of ``folder/name``, a CSV file we did not just write: a regular UTF-8 file inside
    ``folder`` (no link out of it) of at most ``limit`` bytes, with at least one row and every
    one of ``columns``; anything else is one ``error`` naming the file (``missing_hint`` added
    when columns are missing). Nothing is executed."""
    from handover_env.regular_file import read_regular_file

    path = Path(folder) / name
    raw = read_regular_file(path, limit, Path(folder), inside=inside, kind="CSV file",
                            error=error)
    try:
        rows = list(csv.DictReader(io.StringIO(raw.decode("utf-8"), newline="")))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise error(f"{path}: not a UTF-8 CSV file ({exc})") from None
    if not rows:
        raise error(f"{path}: no rows")
    missing = [c for c in columns if c not in rows[0]]
    if missing:
        raise error(f"{path}: no column(s) {missing}{missing_hint}")
    return rows


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """A GitHub-flavoured Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def write_text(text: str, path: str | os.PathLike) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically, creating parent folders."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def write_png(fig: Any, path: str | os.PathLike, dpi: float | None = None) -> Path:
    """Save the matplotlib figure ``fig`` as a PNG at ``path`` atomically, then close it."""
    import matplotlib.pyplot as plt

    try:
        return atomic_write(
            path, lambda f: fig.savefig(f, format="png", **({} if dpi is None else {"dpi": dpi}))
        )
    finally:
        plt.close(fig)


def _fmt_cell(value: object) -> object:
    if isinstance(value, float):
        return f"{value:.6g}"
    return value
