"""Simulated vs recorded reach on replays (handover_eval/closedloop/reach_check.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from handover_eval.closedloop.reach_check import agreement_markdown, reach_agreement


def _rows(sim, ood, arm=None):
    return [
        {"agent": "giver-replay", "set": "replay", "receiver": f"rec{i}", "is_ood": str(o),
         "reach_distance": s, "arm_extended_time": (arm[i] if arm is not None else "nan")}
        for i, (s, o) in enumerate(zip(sim, ood))
    ]


def test_agreement_matches_numpy_per_set_and_skips_what_is_missing():
    rng = np.random.default_rng(0)
    rec = rng.uniform(0.4, 0.6, 40)
    sim = 0.3 + 0.5 * rec + rng.normal(0, 0.02, 40)
    ood = [i % 4 == 0 for i in range(40)]
    arm_sim, arm_rec = rng.uniform(0.5, 1.5, 40), rng.uniform(0.5, 1.5, 40)
    recorded = {f"rec{i}": {"object_shoulder_transfer": rec[i], "arm_extended": arm_rec[i]}
                for i in range(40)}
    rows = _rows(sim, ood, arm_sim)
    rows[1]["reach_distance"] = 0.0  # no grasp: not compared
    recorded["rec2"]["object_shoulder_transfer"] = math.nan  # no recorded transfer
    rows.append({"agent": "reactive", "set": "id", "receiver": "x", "reach_distance": 0.5})
    table = {t["set"]: t for t in reach_agreement(rows, recorded)}
    keep = [i for i in range(40) if i not in (1, 2)]
    for label, sel in (("replay-all", keep), ("replay-ood", [i for i in keep if ood[i]]),
                       ("replay-id", [i for i in keep if not ood[i]])):
        t = table[label]
        assert t["n"] == len(sel)
        assert t["r_reach"] == pytest.approx(np.corrcoef(sim[sel], rec[sel])[0, 1])
        assert t["sim_sd"] == pytest.approx(np.std(sim[sel], ddof=1))
        assert t["rec_median"] == pytest.approx(np.median(rec[sel]))
        assert t["r_arm_out"] == pytest.approx(np.corrcoef(arm_sim[sel], arm_rec[sel])[0, 1])
    assert {t["agent"] for t in table.values()} == {"giver-replay"}  # walkers are not replays
    md = agreement_markdown(list(table.values()))
    assert md.count("\n") == 5 and "giver-replay | replay-ood" in md


def test_too_few_episodes_give_no_row():
    recorded = {"rec0": {"object_shoulder_transfer": 0.5, "arm_extended": 1.0}}
    assert reach_agreement(_rows([0.5], [False]), recorded) == []
