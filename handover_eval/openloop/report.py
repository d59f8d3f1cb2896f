"""Tables and figures of the open-loop experiments (:mod:`.experiments`): Table I in the paper's
layout beside the paper's numbers, the console summaries, the sample-efficiency figure and the
RMS / inference-time figure. Nothing here writes a file (:mod:`.output` does)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.openloop.protocol import OpenLoopProtocol
from handover_eval.reporting import markdown_table, mean_std


def table1_markdown(
    rows: list[dict],
    dataset: HandoverDataset,
    folds: int,
    seed: int,
    protocol: OpenLoopProtocol,
    giver_state: bool = False,
    test_data: HandoverDataset | None = None,
) -> str:
    """Table I in the paper's layout, with the paper's numbers beside ours.

    With ``test_data`` (``--replay-data``) the split sentence says that every method fitted on
    all of ``dataset`` and was scored on every episode of ``test_data``.
    """
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
            roster.label(r["method"]),
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
    if test_data is None:
        split = (
            f"Stratified {folds}-fold split by ID/OOD, seed {seed}; mean ± std over the {folds} "
            "folds of the per-fold mean episode RMS."
        )
    else:
        t_ood = int(test_data.ood_mask.sum())
        split = (
            f"Every method fitted on all of it and scored on every episode of --replay-data "
            f"{test_data.name or 'unnamed'} ({len(test_data) - t_ood} ID + {t_ood} OOD episodes, "
            "none of them in the training data); mean ± std over those episodes."
        )
    return (
        "# Table I: RMS error (mm) of the predicted giver trajectory\n\n"
        + markdown_table(header, body)
        + f"\nDataset: {dataset.name or 'unnamed'} ({len(dataset) - n_ood} ID + {n_ood} OOD "
          "episodes, "
        f"{dataset.n_frames} frames). {split} Protocol: horizon "
        f"{protocol.horizon} frames, "
        f"queries every {protocol.stride} frame(s) from frame {protocol.first_query}. '3D' is the "
        "Euclidean "
        "error over the whole horizon, 'per axis' the same divided by sqrt(3); 'current frame' is "
        "the per-axis "
        "RMS of the first predicted row only (the giver position the planner commands now), the "
        "reading that "
        "matches the paper's numbers (docs/results.md, Open-loop evaluation protocol). The paper's "
        "numbers are on its full public set (900 ID + 100 OOD). Inputs: every method sees the "
        "receiver base "
        "track up to the query frame"
        + (
            ", and BC-MLP / ACT also the giver's position at that frame (--giver-state).\n"
            if giver_state
            else " and nothing else, as in the paper.\n"
        )
    )


def sample_efficiency_figure(rows: list[dict], methods: Sequence[str]) -> Any:
    """Mean ± std markers per method and ratio, values written beside the markers (paper style).

    Two panels, all test episodes: the 1 s horizon RMS (3D) and the current-frame per-axis RMS
    (the reading that matches the paper's Table I). BC-MLP is left out of the picture as in the
    paper (it is in the CSV).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.2), dpi=150)
    markers = {"ours": "o", "iaal": "s", "act": "^", "bc_mlp": "D", "cv": "v"}
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
                x, y, yerr=e, marker=markers.get(name, "o"), capsize=3, label=roster.label(name)
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
    return fig


def tradeoff_figure(rows: list[dict]) -> Any:
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
    return fig


def table1_summary(rows: list[dict]) -> str:
    """Table I for the console: both metrics beside the paper's numbers."""
    header = ["method", "ID 3D (mm)", "OOD 3D (mm)", "ID current frame", "OOD current frame",
              "ID paper", "OOD paper"]
    return markdown_table(header, [
        [
            roster.label(r["method"]),
            mean_std(r["id_rms_3d_mm"], r["id_std_3d_mm"]),
            mean_std(r["ood_rms_3d_mm"], r["ood_std_3d_mm"]),
            mean_std(r["id_now_axis_mm"], r["id_now_axis_std_mm"]),
            mean_std(r["ood_now_axis_mm"], r["ood_now_axis_std_mm"]),
            mean_std(r["paper_id_mm"], r["paper_id_std_mm"]),
            mean_std(r["paper_ood_mm"], r["paper_ood_std_mm"]),
        ]
        for r in rows
    ])


def sample_efficiency_summary(rows: list[dict]) -> str:
    """The sample-efficiency rows for the console."""
    header = ["method", "ratio", "all 3D (mm)", "ID 3D (mm)", "OOD 3D (mm)",
              "all current frame (mm)"]
    return markdown_table(header, [
        [
            roster.label(r["method"]),
            f"{r['ratio']:g}",
            mean_std(r["all_rms_3d_mm"], r["all_std_3d_mm"]),
            mean_std(r["id_rms_3d_mm"], r["id_std_3d_mm"]),
            mean_std(r["ood_rms_3d_mm"], r["ood_std_3d_mm"]),
            mean_std(r["all_now_axis_mm"], r["all_now_axis_std_mm"]),
        ]
        for r in rows
    ])


def degradation_pct(rows: list[dict], key: str = "all_rms_3d_mm") -> dict[str, float]:
    """Per method, how much worse (%) ``key`` is at the smallest training ratio than at the largest.

    The paper's sample-efficiency claim in one number: the nonparametric methods should degrade
    less than ACT as the data shrinks.
    """
    out = {}
    for name in dict.fromkeys(r["method"] for r in rows):
        mine = sorted((r for r in rows if r["method"] == name), key=lambda r: r["ratio"])
        if len(mine) >= 2:
            out[name] = 100.0 * (mine[0][key] / mine[-1][key] - 1.0)
    return out


def degradation_line(rows: list[dict], ratios: Sequence[float]) -> str | None:
    """'RMS at ratio 0.1 vs 1 ...: ACT +12.3% / +4.5%, ...', or None with fewer than two ratios."""
    horizon, now = degradation_pct(rows), degradation_pct(rows, "all_now_axis_mm")
    if not horizon:
        return None
    lo, hi = min(ratios), max(ratios)
    return (
        f"RMS at ratio {lo:g} vs {hi:g} (all episodes, 1 s horizon 3D / current frame): "
        + ", ".join(f"{roster.label(m)} {horizon[m]:+.1f}% / {now[m]:+.1f}%" for m in horizon)
    )


def tradeoff_summary(rows: list[dict]) -> str:
    """The RMS / inference-time rows for the console."""
    header = ["method", "rate", "median ms/frame", "p99 ms/frame", "all 3D (mm)",
              "x faster than IAAL", "RMS vs IAAL"]
    return markdown_table(header, [
        [
            roster.label(r["method"]),
            "" if r["inducing_rate"] is None else f"{r['inducing_rate']:g}",
            f"{r['frame_ms_median']:.3f}",
            f"{r['frame_ms_p99']:.3f}",
            mean_std(r["all_rms_3d_mm"], r["all_std_3d_mm"]),
            f"{r.get('speedup_vs_iaal', float('nan')):.2f}",
            f"{r.get('rms_cost_vs_iaal_pct', float('nan')):+.2f}%",
        ]
        for r in rows
    ])
