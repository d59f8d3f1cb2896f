"""Top-down plots of a handover dataset: receiver (pelvis) and giver (object) paths, ID vs OOD."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from handover_env.data.dataset import HandoverDataset
from handover_env.data.stats import transfer_index
from handover_env.paths import new_file_mode

ID_COLOUR = "tab:blue"
OOD_COLOUR = "tab:red"
#: Image formats ``plot`` writes, chosen by the output's suffix.
FORMATS = (".png", ".pdf", ".svg")


def check_figure_path(out: str | os.PathLike) -> Path:
    """``out`` as a Path, or a ValueError naming it: it must end in a known image suffix and
    must not be a folder (matplotlib would otherwise write ``<out>.png`` beside it)."""
    text = os.fspath(out)
    path = Path(text)
    if not text or path.is_dir() or text.endswith(os.sep):
        raise ValueError(
            f"{text!r}: is a folder; give the output image's file name, e.g. paths.png"
        )
    if path.suffix.lower() not in FORMATS:
        raise ValueError(f"{path}: the output must end in one of {', '.join(FORMATS)}")
    if path.exists() and not path.is_file():
        raise ValueError(f"{path}: exists and is not a regular file")
    return path


def plot_paths(
    dataset: HandoverDataset,
    out: str | os.PathLike,
    max_episodes: int = 200,
    seed: int = 0,
    title: str | None = None,
) -> Path:
    """Draw the receiver and giver paths seen from above and save a PNG.

    Left: receiver pelvis xy (solid) and giver wrist / object xy (dashed), ID in blue and OOD in
    red, transfer points (hand nearest the object) as black dots. Right: object height over time.

    Args:
        dataset: the episodes.
        out: the image path (``.png``, ``.pdf`` or ``.svg``; not a folder).
        max_episodes: at most this many episodes per kind are drawn (a seeded random choice).
        seed: seed of that choice.
        title: figure title; by default the dataset's name and counts.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = check_figure_path(out)
    if len(dataset) == 0:
        raise ValueError("nothing to plot: the dataset is empty")
    rng = np.random.default_rng(seed)
    mask = dataset.ood_mask
    fig, (top, height) = plt.subplots(
        1, 2, figsize=(14, 5.5), gridspec_kw={"width_ratios": [1.4, 1]}
    )
    for is_ood, colour, label in ((False, ID_COLOUR, "ID"), (True, OOD_COLOUR, "OOD")):
        idx = np.flatnonzero(mask == is_ood)
        if idx.size > max_episodes:
            idx = np.sort(rng.choice(idx, max_episodes, replace=False))
        for j, i in enumerate(idx):
            ep = dataset[int(i)]
            k = transfer_index(ep.receiver_hand_xyz, ep.giver_xyz)
            tag = j == 0
            top.plot(
                *ep.receiver_xy.T,
                color=colour,
                lw=0.6,
                alpha=0.5,
                label=f"{label} receiver" if tag else None,
            )
            top.plot(
                *ep.giver_xyz[:, :2].T,
                color=colour,
                lw=0.6,
                ls="--",
                alpha=0.5,
                label=f"{label} giver" if tag else None,
            )
            top.plot(
                *ep.giver_xyz[k, :2], "k.", ms=2.5, label="transfer" if tag and not is_ood else None
            )
            t = np.arange(ep.length) / dataset.rate_hz
            height.plot(t, ep.giver_xyz[:, 2], color=colour, lw=0.6, alpha=0.5)
            height.plot(t[k], ep.giver_xyz[k, 2], "k.", ms=2.5)
    top.plot(0, 0, "k^", ms=8, label="giver (origin)")
    top.set_aspect("equal")
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.legend(loc="upper right", fontsize=7, ncol=2)
    top.grid(alpha=0.3)
    height.set_xlabel("time [s]")
    height.set_ylabel("object (giver wrist) height [m]")
    height.grid(alpha=0.3)
    n_ood = int(mask.sum())
    fig.suptitle(
        title or f"{dataset.name or 'dataset'}: {len(dataset) - n_ood} ID, {n_ood} OOD episodes"
    )
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=out.suffix)
    os.close(fd)
    try:
        fig.savefig(tmp_name, dpi=110, format=out.suffix[1:].lower())
        os.chmod(tmp_name, new_file_mode())
        os.replace(tmp_name, out)  # the reported path is the written one, written whole
    finally:
        plt.close(fig)
        if os.path.exists(tmp_name):
            os.unlink(tmp_name)
    return out
