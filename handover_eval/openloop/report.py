"""Tables and figures of the open-loop experiments (:mod:`.experiments`): Table I in the paper's
layout beside the paper's numbers, the sample-efficiency plot and the RMS / inference-time plot."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from handover_env.data.dataset import HandoverDataset
from handover_eval.openloop.protocol import OpenLoopProtocol
from handover_eval.reporting import METHOD_LABELS, markdown_table, mean_std


def table1_markdown(
    rows: list[dict],
    dataset: HandoverDataset,
    folds: int,
    seed: int,
    protocol: OpenLoopProtocol,
    giver_state: bool = False,
) -> str:
    """Table I in the paper's layout, with the paper's numbers beside ours."""
    header = [
        "Method",
        "ID (ours, 3D)",
        "OOD (ours, 3D)",
        "ID (ours, per axis)",
        "OOD (ours, per axis)",
        "ID (ours, current frame)",
        "OOD (ours, current frame)",
        "ID (paper)",
        "OOD (paper)",
    ]
    body = [
        [
            METHOD_LABELS[r["method"]],
            mean_std(r["id_rms_3d_mm"], r["id_std_3d_mm"]),
            mean_std(r["ood_rms_3d_mm"], r["ood_std_3d_mm"]),
            mean_std(r["id_rms_axis_mm"], r["id_std_axis_mm"]),
            mean_std(r["ood_rms_axis_mm"], r["ood_std_axis_mm"]),
            mean_std(r["id_now_axis_mm"], r["id_now_axis_std_mm"]),
            mean_std(r["ood_now_axis_mm"], r["ood_now_axis_std_mm"]),
            mean_std(r["paper_id_mm"], r["paper_id_std_mm"]),
            mean_std(r["paper_ood_mm"], r["paper_ood_std_mm"]),
        ]
        for r in rows
    ]
    n_ood = int(dataset.ood_mask.sum())
    return (
        "# Table I: RMS error (mm) of the predicted giver trajectory\n\n"
        + markdown_table(header, body)
        + f"\nDataset: {dataset.name or 'unnamed'} ({len(dataset) - n_ood} ID + {n_ood} OOD "
          "episodes, "
        f"{dataset.n_frames} frames). Stratified {folds}-fold split by ID/OOD, seed {seed}; mean "
        "± std over "
        f"the {folds} folds of the per-fold mean episode RMS. Protocol: horizon "
        f"{protocol.horizon} frames, "
        f"queries every {protocol.stride} frame(s) from frame {protocol.first_query}. '3D' is the "
        "Euclidean "
        "error over the whole horizon, 'per axis' the same divided by sqrt(3); 'current frame' is "
        "the per-axis "
        "RMS of the first predicted row only (the giver position the planner commands now), the "
        "reading that "
        "matches the paper's numbers (README, Evaluation protocol). The paper's "
        "numbers are on its full public set (900 ID + 100 OOD). Inputs: every method sees the "
        "receiver base "
        "track up to the query frame"
        + (
            ", and BC-MLP / ACT also the giver's position at that frame (--giver-state).\n"
            if giver_state
            else " and nothing else, as in the paper.\n"
        )
    )


def plot_sample_efficiency(rows: list[dict], methods: Sequence[str], path: Path) -> Path:
    """Mean ± std markers per method and ratio, values written beside the markers (paper style).

    Two panels, all test episodes: the 1 s horizon RMS (3D) and the current-frame per-axis RMS
    (the reading that matches the paper's Table I). BC-MLP is left out of the picture as in the
    paper (it is in the CSV).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.2), dpi=150)
    markers = {"ours": "o", "iaal": "s", "act": "^", "bc_mlp": "D"}
    panels = (("all_rms_3d_mm", "all_std_3d_mm", "RMS error over the 1 s horizon (mm, 3D)"),
              ("all_now_axis_mm", "all_now_axis_std_mm", "current-frame RMS error (mm, per axis)"))
    for ax, (key, std_key, label) in zip(axes, panels, strict=True):
        for k, name in enumerate(methods):
            mine = sorted((r for r in rows if r["method"] == name), key=lambda r: r["ratio"])
            dodge = 0.008 * (
                k - (len(methods) - 1) / 2
            )  # ours and IAAL nearly coincide: keep both visible
            x = [r["ratio"] + dodge for r in mine]
            y = [r[key] for r in mine]
            e = [r[std_key] for r in mine]
            line = ax.errorbar(
                x, y, yerr=e, marker=markers.get(name, "o"), capsize=3, label=METHOD_LABELS[name]
            )
            for xi, yi, ei in zip(
                x, y, e, strict=True
            ):  # staggered so the methods' labels do not overlap
                ax.annotate(
                    mean_std(yi, ei, 1),
                    (xi, yi),
                    textcoords="offset points",
                    xytext=(5, 6 + 8 * k),
                    fontsize=6,
                    color=line.lines[0].get_color(),
                )
        ax.set_xlim(right=max(r["ratio"] for r in rows) + 0.15)  # room for the right-most labels
        ax.set_xlabel("training data ratio")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.suptitle("Sample efficiency (all test episodes; mean ± std over folds)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_tradeoff(rows: list[dict], path: Path) -> Path:
    """RMS (mean ± std over folds) against median per-frame time, one marker per inducing rate."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=150)
    ours = [r for r in rows if r["method"] == "ours"]
    ax.errorbar([r["frame_ms_median"] for r in ours], [r["all_rms_3d_mm"] for r in ours],
                yerr=[r["all_std_3d_mm"] for r in ours], marker="o", capsize=3, label="Ours (SPGP)")
    for r in ours:
        ax.annotate(f"{r['inducing_rate']:g}", (r["frame_ms_median"], r["all_rms_3d_mm"]),
                    textcoords="offset points", xytext=(4, 6), fontsize=7)
    for r in rows:
        if r["method"] == "iaal":
            ax.errorbar(
                [r["frame_ms_median"]],
                [r["all_rms_3d_mm"]],
                yerr=[r["all_std_3d_mm"]],
                marker="*",
                markersize=12,
                capsize=3,
                linestyle="none",
                label="IAAL (exact GP)",
            )
    ax.set_xscale("log")
    ax.set_xlabel(f"inference time per 30 Hz frame (ms, median, 1 core of {os.cpu_count()})")
    ax.set_ylabel("RMS error (mm, 3D)")
    ax.set_title("RMS error vs inference time (labels: inducing rate)")
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
