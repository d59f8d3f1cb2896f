"""Figures of the receiver calibration: traces aligned on the transfer, and the reach onset.

Both show distributions over the recordings of the calibration half (medians, 25-75 % bands and
histograms), never a single recording.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handover_env.data.detect import RATE_HZ
from handover_eval.calibration.measures import trace_lags
from handover_eval.reporting import write_png

#: Plot a lag only where at least this many recordings have a value.
MIN_RECORDINGS = 10
ALIGNED_NAME, ONSET_NAME = "aligned_on_transfer.png", "reach_onset.png"
_PANELS = (
    ("d15", "hand (15) to object, m"),
    ("giver", "giver hand to object\nbeyond holding, m"),
    ("speed", "walking speed /\npre-reach speed"),
    ("rise", "hand above its\nwalking height, m"),
)
_COLORS = {False: "tab:blue", True: "tab:red"}


def _band(ax, t: np.ndarray, rows: np.ndarray, color: str, label: str) -> None:
    ok = np.isfinite(rows).sum(axis=0) >= MIN_RECORDINGS
    if not ok.any():
        return
    q25, q50, q75 = np.nanpercentile(rows[:, ok], [25, 50, 75], axis=0)
    ax.fill_between(t[ok], q25, q75, color=color, alpha=0.2, lw=0)
    ax.plot(t[ok], q50, color=color, lw=1.5, label=label)


def write_figures(results: list, out_dir: str | Path) -> list[Path]:
    """Write the two PNGs for the calibration half of ``results``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    chosen = [r for r in results if r.calibration and r.analysis.events["transfer"] is not None]
    t = trace_lags(RATE_HZ) / RATE_HZ
    fig, axes = plt.subplots(len(_PANELS), 1, figsize=(7.5, 9.5), sharex=True)
    for ax, (key, ylabel) in zip(axes, _PANELS):
        for ood in (False, True):
            rows = [
                r.analysis.traces[key]
                for r in chosen
                if r.is_ood == ood and key in r.analysis.traces
            ]
            if rows:
                label = f"{'OOD' if ood else 'ID'} (n={len(rows)}): median, 25-75 %"
                _band(ax, t, np.vstack(rows), _COLORS[ood], label)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    for name, style in (("reach_duration", ":"), ("hold_duration", "--")):
        values = [r.analysis.measures[name] for r in chosen if not r.is_ood]
        values = np.asarray(values)[np.isfinite(values)]
        if values.size:
            x = -np.median(values) if name == "reach_duration" else np.median(values)
            what = "reach onset" if name == "reach_duration" else "giver release"
            for ax in axes:
                ax.axvline(x, color="0.4", ls=style, lw=0.9, label=f"median ID {what}")
    axes[0].legend(fontsize=7, loc="upper right")
    axes[2].axhline(1.0, color="0.5", lw=0.6)
    axes[-1].set_xlabel("time from the transfer (receiver's hand takes the object), s")
    fig.suptitle("Recorded handovers aligned on the transfer (calibration half)")
    fig.tight_layout()
    aligned = write_png(fig, out / ALIGNED_NAME, dpi=110)

    panels = (
        (
            "object_shoulder_onset",
            "object to right shoulder at onset, m",
            np.arange(0.3, 1.81, 0.05),
        ),
        ("ttc_onset", "time to contact at onset, s", np.arange(0.0, 3.01, 0.1)),
        ("reach_duration", "reach duration (onset to transfer), s", np.arange(0.0, 2.01, 1 / 15)),
    )
    fig, axes = plt.subplots(1, len(panels), figsize=(12, 3.4))
    for ax, (name, xlabel, bins) in zip(axes, panels):
        for ood in (False, True):
            v = np.array([r.analysis.measures[name] for r in chosen if r.is_ood == ood])
            v = v[np.isfinite(v)]
            if v.size:
                ax.hist(np.clip(v, bins[0], bins[-1]), bins=bins, density=True, histtype="step",
                        color=_COLORS[ood], lw=1.5,
                        label=f"{'OOD' if ood else 'ID'} (n={v.size}), median {np.median(v):.2f}")
        ax.set_xlabel(xlabel)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("density (values clipped to the axis)")
    fig.suptitle("When people start to reach (calibration half)")
    fig.tight_layout()
    onset = write_png(fig, out / ONSET_NAME, dpi=110)
    return [aligned, onset]
