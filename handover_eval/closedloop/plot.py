"""``closed_loop.png``: success rate with its CI, handover-time distributions and effort measures
per agent and receiver set (the simulated person): scripted ID and OOD walkers, replayed ID and OOD
recordings, one colour each (``replay-all`` pools the last two and is left to the tables)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from handover_eval import roster
from handover_eval.closedloop.report import groups_of

SET_COLOURS = {
    "walker-id": "tab:blue",
    "walker-ood": "tab:orange",
    "replay-id": "tab:green",
    "replay-ood": "tab:red",
}
PANELS = (
    ("handover_time", "handover time (s), successes"),
    ("time_lost", "time lost slowing down (s)"),
    ("arm_extended_time", "arm extended (s)"),
    ("reach_distance", "reach distance (m)"),
    ("body_contact_force", "peak robot-body contact (N)"),
)


def _values(rows: Sequence[dict], agent: str, rset: str, col: str) -> np.ndarray:
    v = np.array(
        [float(r[col]) for r in rows if r["agent"] == agent and rset in groups_of(r)],
        dtype=float,
    )
    return v[np.isfinite(v)]


def closed_loop_figure(rows: Sequence[dict], agg: Sequence[dict], title: str) -> Any:
    """Six panels: success rate (Wilson 95 % CI) and five per-episode distributions (box plots)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agents = list(dict.fromkeys(r["agent"] for r in agg))
    sets = [s for s in SET_COLOURS if any(r["set"] == s for r in agg)]
    width = 0.8 / max(1, len(sets))
    fig, axes = plt.subplots(2, 3, figsize=(max(12.0, 1.7 * len(agents)), 7.5), dpi=130)
    axes = axes.ravel()
    x = np.arange(len(agents))
    ax = axes[0]
    for k, s in enumerate(sets):
        mine = {r["agent"]: r for r in agg if r["set"] == s}
        xs = [x[i] + (k - (len(sets) - 1) / 2) * width for i, a in enumerate(agents) if a in mine]
        rate = [100 * mine[a]["success_rate"] for a in agents if a in mine]
        # max(0, ...): a Wilson bound at a rate of 0 or 1 can miss it by a rounding error
        low = [
            max(0.0, 100 * (mine[a]["success_rate"] - mine[a]["success_low"]))
            for a in agents if a in mine
        ]
        high = [
            max(0.0, 100 * (mine[a]["success_high"] - mine[a]["success_rate"]))
            for a in agents if a in mine
        ]
        ax.bar(xs, rate, width, color=SET_COLOURS[s], alpha=0.8, label=s)
        ax.errorbar(xs, rate, yerr=[low, high], fmt="none", ecolor="k", capsize=2, lw=0.8)
    ax.set_ylabel("success rate (%), 95 % Wilson CI")
    ax.set_ylim(0, 105)
    ax.legend(fontsize=7, loc="lower left")
    for ax, (col, label) in zip(axes[1:], PANELS, strict=True):
        for k, s in enumerate(sets):
            data, pos = [], []
            for i, a in enumerate(agents):
                v = _values(rows, a, s, col) if col in rows[0] else np.array([])
                if v.size:
                    data.append(v)
                    pos.append(x[i] + (k - (len(sets) - 1) / 2) * width)
            if data:
                bp = ax.boxplot(
                    data,
                    positions=pos,
                    widths=width * 0.9,
                    patch_artist=True,
                    showfliers=True,
                    flierprops={"markersize": 2},
                )
                for box in bp["boxes"]:
                    box.set_facecolor(SET_COLOURS[s])
                    box.set_alpha(0.6)
        ax.set_ylabel(label)
    for ax in axes:
        ax.set_xticks(x)
        ax.set_xticklabels(
            [roster.label(a).split(" (")[0] for a in agents], rotation=30, ha="right", fontsize=8
        )
        ax.grid(alpha=0.3, axis="y")
        ax.set_xlim(-0.6, len(agents) - 0.4)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig
