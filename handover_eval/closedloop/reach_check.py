"""Simulated against recorded reach on the replays (issue 23's acceptance on the reach).

For each replayed recording, the recordings' own statistics (:mod:`handover_eval.calibration`):
``object_shoulder_transfer`` (right shoulder to the object's centre when the receiver took it)
and ``arm_extended`` (reach onset to the hand drawn back to the body); the env's are
``reach_distance`` (defined as the first, on the simulated body) and ``arm_extended_time`` (the
arm out before the release: a different span, so its correlation is the question, not its
level). :func:`reach_agreement` compares them per agent and receiver set over the episodes in
which both exist: medians, SDs, and Pearson's r per recording.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from handover_eval.closedloop.stats import cell_float

RECORDED = ("object_shoulder_transfer", "arm_extended")
SIMULATED = ("reach_distance", "arm_extended_time")


def recorded_measures(folder: str | Path, names: Iterable[str]) -> dict[str, dict[str, float]]:
    """``name -> {measure: value}`` of :data:`RECORDED` for each recording ``folder/name.pkl``
    (loaded with the dataset's safe unpickler; NaN where the recording has no transfer)."""
    from handover_eval.calibration.report import analyse_file

    out = {}
    for name in sorted(set(names)):
        m = analyse_file(Path(folder) / f"{name}.pkl").analysis.measures
        out[name] = {k: float(m.get(k, math.nan)) for k in RECORDED}
    return out


def reach_agreement(
    rows: Sequence[Mapping[str, object]], recorded: Mapping[str, Mapping[str, float]]
) -> list[dict[str, float | str | int]]:
    """Per agent and replay set (``replay-id``, ``replay-ood``, ``replay-all``): over the
    episodes with a grasp (``reach_distance > 0``) of a recording with a transfer, the simulated
    and recorded reach's median and SD, r per recording, and r of the arm-out times."""
    out = []
    agents = list(dict.fromkeys(str(r["agent"]) for r in rows if r.get("set") == "replay"))
    for agent in agents:
        for label, want in (("replay-id", "False"), ("replay-ood", "True"), ("replay-all", None)):
            sim, rec, sim_arm, rec_arm = [], [], [], []
            for r in rows:
                if r.get("agent") != agent or r.get("set") != "replay":
                    continue
                if want is not None and str(r.get("is_ood")) != want:
                    continue
                got = recorded.get(str(r["receiver"]))
                s = cell_float(r.get("reach_distance"))
                if got is None or not s > 0 or not math.isfinite(got[RECORDED[0]]):
                    continue
                sim.append(s)
                rec.append(got[RECORDED[0]])
                a, b = cell_float(r.get("arm_extended_time")), got[RECORDED[1]]
                if math.isfinite(a) and math.isfinite(b):
                    sim_arm.append(a)
                    rec_arm.append(b)
            if len(sim) < 3:
                continue
            s_arr, r_arr = np.array(sim), np.array(rec)
            out.append({
                "agent": agent, "set": label, "n": len(sim),
                "sim_median": float(np.median(s_arr)), "rec_median": float(np.median(r_arr)),
                "sim_sd": float(np.std(s_arr, ddof=1)), "rec_sd": float(np.std(r_arr, ddof=1)),
                "r_reach": float(np.corrcoef(s_arr, r_arr)[0, 1]),
                "n_arm": len(sim_arm),
                "r_arm_out": float(np.corrcoef(sim_arm, rec_arm)[0, 1])
                if len(sim_arm) >= 3 else math.nan,
            })
    return out


def agreement_markdown(table: Sequence[Mapping[str, float | str | int]]) -> str:
    """The table of :func:`reach_agreement` as Markdown."""
    lines = [
        "| agent | set | n | reach median sim / rec (m) | SD sim / rec (m) | SD ratio | r reach "
        "| r arm out |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for t in table:
        lines.append(
            f"| {t['agent']} | {t['set']} | {t['n']} | {t['sim_median']:.3f} / "
            f"{t['rec_median']:.3f} | {t['sim_sd']:.3f} / {t['rec_sd']:.3f} | "
            f"{float(t['sim_sd']) / float(t['rec_sd']):.2f} | {t['r_reach']:+.2f} | "
            f"{t['r_arm_out']:+.2f} |"
        )
    return "\n".join(lines) + "\n"
