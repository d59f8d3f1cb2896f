"""Where and how each agent presents the bottle, against the recorded human givers (issue 36: a
policy must not win by presenting as no giver did).

At the person's grasp the env states (``info``, :class:`handover_env.envs.base_handover`):
``transfer_object_body`` (the bottle's centre forward, left and up of the pelvis in the person's
walking frame; closed-loop columns ``transfer_object_fwd/lat/up``), ``transfer_object_speed``
(m/s) and ``transfer_robot_jerk`` (the TCP's third difference over the last four 30 Hz steps,
m/s³). The recordings' counterparts at the detected transfer are the calibration measures
``object_fwd/lat/up_transfer``, ``object_speed_transfer`` and ``object_jerk_transfer_raw`` (the
same jerk estimator on the unsmoothed object track: the env's TCP is not smoothed either)
(:mod:`handover_eval.calibration.measures`).

:func:`recorded_ranges` takes their 5-95 % range over the calibration half of the recordings
(Table I's folds 0-4, as every calibrated number of the person); :func:`presentation_table`
counts, per agent and receiver set, the grasps below and above it. A recorded person leaves a
5-95 % range 10 % of the time by construction; an agent whose grasps leave it much more often
presents where no recorded giver did, and a gain that comes from there is the simulated
person's, not a result (docs/rl.md).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence

import numpy as np

from handover_eval.closedloop.stats import cell_float
from handover_eval.reporting import markdown_table

#: closed-loop column -> (recorded measure, what, unit, digits)
QUANTITIES: dict[str, tuple[str, str, str, int]] = {
    "transfer_object_fwd": ("object_fwd_transfer", "forward of the pelvis", "m", 3),
    "transfer_object_lat": ("object_lat_transfer", "lateral of the pelvis (+ left)", "m", 3),
    "transfer_object_up": ("object_up_transfer", "above the pelvis", "m", 3),
    "transfer_object_speed": ("object_speed_transfer", "bottle speed", "m/s", 2),
    "transfer_robot_jerk": ("object_jerk_transfer_raw", "jerk (robot TCP / giver's bottle)",
                            "m/s³", 1),
}
LOW_Q, HIGH_Q = 0.05, 0.95
#: receiver sets of the table: (label, closed-loop ``set``, ``is_ood`` of a replay or None)
SETS = (("walker-id", "id", None), ("walker-ood", "ood", None),
        ("replay-id", "replay", "False"), ("replay-ood", "replay", "True"),
        ("replay-all", "replay", None))


def recorded_ranges(
    folder: str | os.PathLike, *, folds: int = 10, seed: int = 0, calibration_folds: int = 5,
    progress: bool = True,
) -> dict[str, dict[str, float]]:
    """``measure -> {"low", "high", "median", "n"}``: the 5 %, 95 % and 50 % quantiles of each
    recorded measure of :data:`QUANTITIES` over the calibration half's recordings with a
    transfer (dataset files loaded with the safe unpickler, nothing written)."""
    from handover_eval.calibration.report import analyse_folder, assign_halves

    results, _ = analyse_folder(folder, progress=progress)
    assign_halves(results, folds, seed, calibration_folds)
    out = {}
    for measure, *_ in QUANTITIES.values():
        v = np.array([r.analysis.measures[measure] for r in results if r.calibration])
        v = v[np.isfinite(v)]
        if v.size < 20:
            raise ValueError(f"{folder}: only {v.size} calibration recording(s) measure "
                             f"{measure}: no 5-95 % range")
        out[measure] = {"low": float(np.quantile(v, LOW_Q)), "high": float(np.quantile(v, HIGH_Q)),
                        "median": float(np.median(v)), "n": int(v.size)}
    return out


def _members(rows: Sequence[Mapping[str, object]], agent: str, kind: str,
             ood: str | None) -> list[Mapping[str, object]]:
    return [r for r in rows if r.get("agent") == agent and r.get("set") == kind
            and (ood is None or str(r.get("is_ood")) == ood)
            and math.isfinite(cell_float(r.get("transfer_object_fwd")))]


def presentation_table(
    rows: Sequence[Mapping[str, object]], ranges: Mapping[str, Mapping[str, float]]
) -> list[dict[str, object]]:
    """Per agent and set of :data:`SETS` with a grasp: ``n`` grasps, and per quantity its median
    and the share of grasps below (``<col>_below``) and above (``<col>_above``) the recorded
    range; ``any_outside``: the share with at least one position or speed quantity outside
    (jerk apart: its ranges are not alike, see the module docstring)."""
    agents = list(dict.fromkeys(str(r.get("agent")) for r in rows))
    out: list[dict[str, object]] = []
    for agent in agents:
        for label, kind, ood in SETS:
            members = _members(rows, agent, kind, ood)
            if not members:
                continue
            row: dict[str, object] = {"agent": agent, "set": label, "n": len(members)}
            outside = np.zeros(len(members), dtype=bool)
            for col, (measure, *_rest) in QUANTITIES.items():
                v = np.array([cell_float(m.get(col)) for m in members])
                lo, hi = ranges[measure]["low"], ranges[measure]["high"]
                below, above = v < lo, v > hi
                row[f"{col}_median"] = float(np.nanmedian(v)) if np.isfinite(v).any() else math.nan
                row[f"{col}_below"] = float(below.mean())
                row[f"{col}_above"] = float(above.mean())
                if col != "transfer_robot_jerk":
                    outside |= below | above
            row["any_outside"] = float(outside.mean())
            out.append(row)
    return out


def _pct(v: object) -> str:
    return f"{100.0 * float(v):.0f} %"  # type: ignore[arg-type]


def markdown(table: Sequence[Mapping[str, object]], ranges: Mapping[str, Mapping[str, float]],
             source: str = "") -> str:
    """The ranges and the table as a Markdown page."""
    text = "# Presentation at the grasp against the recorded givers\n\n"
    if source:
        text += f"Episodes: `{source}`.\n\n"
    text += ("The recorded range is the 5-95 % range over the calibration half's recordings "
             "(Table I folds 0-4); a recorded giver leaves it 10 % of the time by construction. "
             "Per quantity: the median, and the share of grasps below / above the range. "
             "'outside': at least one position or speed quantity out of range.\n\n")
    text += markdown_table(
        ("quantity", "recorded measure", "unit", "median", "5-95 % range", "n"),
        [(what, f"`{m}`", unit, f"{ranges[m]['median']:.{d}f}",
          f"[{ranges[m]['low']:.{d}f}, {ranges[m]['high']:.{d}f}]", ranges[m]["n"])
         for m, what, unit, d in QUANTITIES.values()],
    )
    text += "\n"
    header = ["agent", "set", "grasps", *(QUANTITIES[c][1] for c in QUANTITIES), "outside"]
    body = []
    for t in table:
        cells = [t["agent"], t["set"], t["n"]]
        for col, (_, _, _, d) in QUANTITIES.items():
            cells.append(f"{float(t[f'{col}_median']):.{d}f} ({_pct(t[f'{col}_below'])} / "  # type: ignore[arg-type]
                         f"{_pct(t[f'{col}_above'])})")
        cells.append(_pct(t["any_outside"]))
        body.append(cells)
    text += markdown_table(header, body)
    return text


def figure(rows: Sequence[Mapping[str, object]], ranges: Mapping[str, Mapping[str, float]],
           label: str = "replay-all"):  # type: ignore[no-untyped-def]
    """Box plots of each quantity per agent on the set ``label``, the recorded range shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kind, ood = next((k, o) for lab, k, o in SETS if lab == label)
    agents = [a for a in dict.fromkeys(str(r.get("agent")) for r in rows)
              if _members(rows, a, kind, ood)]
    fig, axes = plt.subplots(1, len(QUANTITIES), figsize=(3.2 * len(QUANTITIES), 3.6))
    for ax, (col, (measure, what, unit, _)) in zip(axes, QUANTITIES.items(), strict=True):
        data = [np.array([cell_float(m.get(col)) for m in _members(rows, a, kind, ood)])
                for a in agents]
        data = [d[np.isfinite(d)] for d in data]
        r = ranges[measure]
        ax.axhspan(r["low"], r["high"], color="tab:orange", alpha=0.25, label="recorded 5-95 %")
        ax.boxplot(data, showfliers=False)
        ax.set_xticks(range(1, len(agents) + 1), agents, rotation=60, fontsize=7)
        ax.set_title(f"{what} ({unit})", fontsize=8)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"presentation at the grasp, {label}", fontsize=9)
    fig.tight_layout()
    return fig


#: The largest episodes file read (a full closed-loop run of every agent is a few MiB).
MAX_EPISODES_BYTES = 64 << 20


class PresentationError(ValueError):
    """An episodes file that cannot be read as a closed-loop run's."""


def read_episode_rows(run_folder: str | os.PathLike) -> list[dict[str, str]]:
    """The rows of ``run_folder/closed_loop_episodes.csv``: a regular UTF-8 file inside the
    folder (no link out of it) of at most :data:`MAX_EPISODES_BYTES`; nothing is executed."""
    from handover_eval.reporting import read_folder_csv

    return read_folder_csv(run_folder, "closed_loop_episodes.csv", MAX_EPISODES_BYTES,
                           ("agent", "set", "is_ood", *QUANTITIES), PresentationError,
                           inside="run folder", missing_hint=" (a closed-loop run from before "
                           "the env stated the presentation at the grasp?)")


def run_presentation(
    run_folder: str | os.PathLike, data: str | os.PathLike, *, progress: bool = True,
) -> tuple[list[dict[str, str]], dict[str, dict[str, float]], list[dict[str, object]]]:
    """``(episode rows, recorded ranges, table)`` of the closed-loop run in ``run_folder`` and
    the recordings of ``data`` (the public dataset's ``whole_motions`` folder)."""
    rows = read_episode_rows(run_folder)
    ranges = recorded_ranges(data, progress=progress)
    return rows, ranges, presentation_table(rows, ranges)


__all__ = ["QUANTITIES", "PresentationError", "figure", "markdown", "presentation_table",
           "read_episode_rows", "recorded_ranges", "run_presentation"]
