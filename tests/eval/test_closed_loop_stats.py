"""Statistics of the closed-loop tables against closed forms, and the pairing of receivers."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from handover_eval.closedloop.markdown import markdown
from handover_eval.closedloop.report import aggregate, ghosts, groups_of, paired
from handover_eval.closedloop.stats import (
    bootstrap_ci,
    median_iqr,
    pair_up,
    paired_difference,
    stable_seed,
    wilson_interval,
)


@pytest.mark.parametrize(
    ("k", "n", "low", "high"),
    [
        (5, 10, 0.236593, 0.763407),
        (1, 20, 0.008881, 0.236130),
        (10, 10, 0.722467, 1.0),
        (50, 100, 0.403832, 0.596168),
    ],
)
def test_wilson_interval_matches_tabulated_values(k: int, n: int, low: float, high: float) -> None:
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(low, abs=2e-6)
    assert hi == pytest.approx(high, abs=2e-6)


def test_wilson_interval_closed_form_at_zero_successes() -> None:
    """k = 0: the interval is [0, z^2 / (n + z^2)]."""
    z = 1.959963984540054
    for n in (1, 7, 50):
        lo, hi = wilson_interval(0, n)
        assert lo == pytest.approx(0.0, abs=1e-12)
        assert hi == pytest.approx(z * z / (n + z * z), rel=1e-12)
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    with pytest.raises(ValueError, match="k <= n"):
        wilson_interval(3, 2)


def test_bootstrap_ci_is_seeded_and_handles_degenerate_samples() -> None:
    x = np.random.default_rng(1).normal(size=30)
    assert bootstrap_ci(x, seed=4) == bootstrap_ci(x, seed=4)
    assert bootstrap_ci(x, seed=4) != bootstrap_ci(x, seed=5)
    est, lo, hi = bootstrap_ci(np.r_[x, np.nan, np.inf], seed=4)  # non-finite values are dropped
    assert (est, lo, hi) == bootstrap_ci(x, seed=4)
    assert est == pytest.approx(np.median(x)) and lo < est < hi
    assert bootstrap_ci(np.full(12, 2.5)) == (2.5, 2.5, 2.5)
    assert bootstrap_ci([7.0]) == (7.0, 7.0, 7.0)
    assert all(math.isnan(v) for v in bootstrap_ci([]))
    assert bootstrap_ci([1.0, 2.0, 3.0], stat="mean", n_boot=50)[0] == pytest.approx(2.0)
    with pytest.raises(ValueError, match="median"):
        bootstrap_ci(x, stat="mode")


def test_paired_bootstrap_covers_a_known_median_difference() -> None:
    """Pairs whose differences have median 0.3: the CI covers 0.3 about 95 % of the time."""
    rng = np.random.default_rng(0)
    covered, excluded_zero = 0, 0
    trials = 200
    for t in range(trials):
        ref = rng.normal(2.0, 1.0, size=40)  # the receivers differ a lot ...
        agent = ref + 0.3 + rng.laplace(0.0, 0.2, size=40)  # ... the paired difference little
        d = paired_difference(agent, ref, "median", n_boot=1000, seed=t)
        covered += d.low <= 0.3 <= d.high
        excluded_zero += d.excludes_zero
    assert 0.88 <= covered / trials <= 0.99
    assert excluded_zero == trials  # pairing removes the between-receiver spread


def test_paired_success_difference_is_a_difference_in_rates() -> None:
    agent = np.array([1, 1, 1, 0, 1, 1, 1, 1, 1, 1], dtype=float)
    ref = np.array([1, 0, 0, 0, 1, 0, 0, 1, 0, 0], dtype=float)
    d = paired_difference(agent, ref, "mean", seed=0)
    assert d.n == 10 and d.diff == pytest.approx(0.9 - 0.3)
    assert d.agent == pytest.approx(0.9) and d.reference == pytest.approx(0.3)
    assert d.low <= d.diff <= d.high and d.excludes_zero
    same = paired_difference(ref, ref, "mean")
    assert (same.diff, same.low, same.high, same.excludes_zero) == (0.0, 0.0, 0.0, False)
    empty = paired_difference([], [], "mean")
    assert empty.n == 0 and not empty.excludes_zero
    with pytest.raises(ValueError, match="length"):
        paired_difference([1.0], [1.0, 2.0])


def test_pair_up_aligns_by_key_and_drops_missing_values() -> None:
    ref = {"a": 1.0, "b": 2.0, "c": None, "d": 4.0, "e": 5.0}
    agent = {"e": 50.0, "d": float("nan"), "b": 20.0, "a": 10.0, "z": 9.0}
    keys, a, r = pair_up(agent, ref)
    assert keys == ["a", "b", "e"]
    np.testing.assert_array_equal(a, [10.0, 20.0, 50.0])
    np.testing.assert_array_equal(r, [1.0, 2.0, 5.0])


def _row(agent: str, rset: str, receiver: str, outcome: str, **values) -> dict:
    row = {"agent": agent, "set": rset, "receiver": receiver, "outcome": outcome,
           "is_success": outcome == "success", "release_before_grasp": False}
    row.update(values)
    return row


def test_paired_rows_match_receivers_not_row_order() -> None:
    """Shuffled rows, an extra receiver and a receiver key shared by two sets change nothing."""
    rows = []
    for i in range(8):
        t = 2.0 + 0.1 * i
        rows.append(_row("reactive", "id", f"r{i}", "success", handover_time=t, time_lost=0.0))
        rows.append(_row("lagging", "id", f"r{i}", "success", handover_time=t + 0.5, time_lost=0.1))
        rows.append(_row("reactive", "ood", f"r{i}", "success", handover_time=t, time_lost=0.0))
        rows.append(_row("lagging", "ood", f"r{i}", "missed", handover_time=None, time_lost=1.0))
    rows.append(_row("lagging", "id", "only-lagging", "success", handover_time=99.0, time_lost=9.0))
    metrics = {"success": ("is_success", "mean"), "handover_time": ("handover_time", "median"),
               "time_lost": ("time_lost", "median")}
    out = paired(rows, n_boot=200, metrics=metrics)
    shuffled = rows[:]
    random.Random(3).shuffle(shuffled)
    assert sorted(map(str, paired(shuffled, n_boot=200, metrics=metrics))) == sorted(map(str, out))
    by = {(d["set"].removeprefix("walker-"), d["metric"]): d for d in out}
    assert by[("id", "handover_time")]["n_pairs"] == 8
    assert by[("id", "handover_time")]["diff"] == pytest.approx(0.5)
    assert by[("id", "handover_time")]["ci_excludes_zero"]
    assert by[("id", "success")]["diff"] == 0.0
    assert by[("ood", "success")]["diff"] == -1.0
    assert by[("ood", "handover_time")]["n_pairs"] == 0  # no receiver where both succeeded
    assert by[("ood", "time_lost")]["diff"] == pytest.approx(1.0)
    assert by[("ood", "time_lost")]["mean_diff"] == pytest.approx(1.0)
    assert by[("id", "time_lost")]["mean_excludes_zero"]
    assert stable_seed("a", 1) == stable_seed("a", 1) != stable_seed("a", 2)


def test_aggregate_and_ghosts_count_what_they_say() -> None:
    rows = [
        _row(
            "x",
            "id",
            "1",
            "success",
            handover_time=2.0,
            penetration=0.001,
            body_contact_force=0.0,
            peak_contact_force=10.0,
            transfer_pelvis_x=0.5,
        ),
        _row(
            "x",
            "id",
            "2",
            "success",
            handover_time=4.0,
            penetration=0.004,
            body_contact_force=30.0,
            peak_contact_force=30.0,
            transfer_pelvis_x=0.7,
        ),
        _row(
            "x",
            "id",
            "3",
            "premature_release",
            handover_time=None,
            penetration=0.0,
            body_contact_force=5.0,
            peak_contact_force=12.0,
            transfer_pelvis_x=None,
            release_before_grasp=True,
        ),
        _row(
            "x",
            "id",
            "4",
            "timeout",
            handover_time=None,
            penetration=0.02,
            body_contact_force=0.0,
            peak_contact_force=9.0,
            transfer_pelvis_x=None,
        ),
    ]
    (agg,) = aggregate(rows)
    assert agg["n"] == 4 and agg["success_rate"] == 0.5
    assert (agg["success_low"], agg["success_high"]) == pytest.approx(
        (0.150036, 0.849964), abs=1e-5)  # Wilson 2/4
    assert (agg["n_success"], agg["n_premature_release"], agg["n_timeout"], agg["n_missed"]) == (
        2,
        1,
        1,
        0,
    )
    assert agg["handover_time_n"] == 2 and agg["handover_time_median"] == 3.0  # successes only
    assert (
        median_iqr(np.array([0.5, 0.7]))[0] == agg["transfer_pelvis_x_median"] == pytest.approx(0.6)
    )
    assert agg["penetration_max"] == 0.02
    assert agg["release_before_grasp_successes"] == 0  # the premature release is not a success
    g = {r["agent"]: r for r in ghosts(rows) if r["set"] == "all"}
    assert g["all"]["episodes_penetration_over_1cm"] == 1
    assert g["all"]["successes_release_before_grasp"] == 0
    assert g["x"]["episodes_with_body_contact"] == 2
    assert g["x"]["body_contact_force_max"] == 30.0 and g["x"]["body_contact_force_q50"] == 2.5


def test_replays_are_split_by_is_ood_in_every_table() -> None:
    """35 ID replays that all succeed and 6 OOD replays of which 2 fail: the pooled replay rate
    (95 %) hides what replay-ood shows (67 %); the walkers stay apart too."""
    rows = []
    for agent, fail_ood in (("reactive", False), ("x", True)):
        for i in range(35):
            rows.append(_row(agent, "replay", f"n{i}", "success", is_ood=False, handover_time=3.0))
        for i in range(6):
            bad = fail_ood and i < 2
            rows.append(_row(agent, "replay", f"v{i}", "missed" if bad else "success",
                             is_ood="True", handover_time=None if bad else 3.5))
        rows.append(_row(agent, "id", "w0", "success", is_ood=False, handover_time=2.0))
        rows.append(_row(agent, "ood", "w1", "success", is_ood=True, handover_time=2.5))
    assert groups_of(rows[0]) == ("replay-id", "replay-all")
    assert groups_of(rows[35]) == ("replay-ood", "replay-all")  # is_ood read from CSV text
    assert groups_of(rows[-1]) == ("walker-ood",)
    with pytest.raises(ValueError, match="receiver set"):
        groups_of({"set": "bogus"})
    agg = {(a["agent"], a["set"]): a for a in aggregate(rows)}
    assert [s for a, s in agg if a == "x"] == [
        "walker-id", "walker-ood", "replay-id", "replay-ood", "replay-all"
    ]
    assert agg[("x", "replay-id")]["n"] == 35 and agg[("x", "replay-id")]["success_rate"] == 1.0
    assert agg[("x", "replay-ood")]["n"] == 6
    assert agg[("x", "replay-ood")]["success_rate"] == pytest.approx(4 / 6)
    assert agg[("x", "replay-all")]["success_rate"] == pytest.approx(39 / 41)
    pairs = {(d["set"], d["metric"]): d for d in paired(rows, n_boot=200)}
    assert pairs[("replay-ood", "success")]["diff"] == pytest.approx(-2 / 6)
    assert pairs[("replay-ood", "success")]["n_pairs"] == 6
    assert pairs[("replay-id", "success")]["diff"] == 0.0
    assert pairs[("replay-all", "success")]["n_pairs"] == 41
    g = {(r["agent"], r["set"]): r for r in ghosts(rows)}
    assert g[("all", "all")]["n"] == len(rows) and g[("x", "replay-ood")]["n"] == 6
    assert g[("all", "walker-id")]["n"] == 2
    text = markdown(aggregate(rows), paired(rows, n_boot=200), ghosts(rows), "# t\n")
    for group in ("walker-id", "walker-ood", "replay-id", "replay-ood", "replay-all"):
        assert f"| {group} |" in text
    assert "67 % [" in text  # x on replay-ood


def test_theta_sweep_summarises_every_receiver_group_apart() -> None:
    from handover_eval.closedloop.theta_sweep import METRICS, summarise, sweep_groups, verdicts

    blank = {column: 0.0 for column, _, _ in METRICS.values()}
    rows = []
    for value, release in ((5.0, 6.0), (20.0, 21.0)):
        for i in range(4):
            for rset, ood in (("id", False), ("replay", False), ("replay", True)):
                # OOD replays fail at the high end: only replay-ood (and the pooled sets) move
                bad = ood and value == 20.0
                rows.append(_row("reactive", rset, f"{rset}{ood}{i}",
                                 "missed" if bad else "success",
                                 **{**blank, "release_force": release, "handover_time": 3.0},
                                 is_ood=ood, param="release_force", value=value))
                rows[-1]["is_success"] = not bad
    assert sweep_groups(rows) == ["all", "walker-id", "replay-id", "replay-ood", "replay-all"]
    per_value, extremes = summarise(rows, n_boot=200)
    n = {(r["set"], r["value"]): r["n"] for r in per_value if r["metric"] == "release_force"}
    assert n[("all", 5.0)] == 12 and n[("replay-ood", 5.0)] == 4 and n[("replay-all", 20.0)] == 8
    ext = {(e["set"], e["metric"]): e for e in extremes}
    assert ext[("replay-ood", "success")]["diff"] == -1.0
    assert ext[("replay-id", "success")]["diff"] == 0.0
    assert ext[("walker-id", "release_force")]["diff"] == pytest.approx(15.0)
    moved = {(v["set"]): v["outcomes_moved"] for v in verdicts(extremes)}
    assert "success" in moved["replay-ood"] and "success" not in moved["replay-id"]


def test_a_verdict_gives_no_percentage_against_a_zero_reference():
    """A summed 0 s (time lost, ~1e-17 s by rounding) is not a base for a relative change."""
    from handover_eval.closedloop.theta_sweep import verdicts

    base = {"param": "forecast_time", "set": "all", "ci_excludes_zero": True,
            "diff_low": 0.03, "diff_high": 0.08}
    (v,) = verdicts([{**base, "metric": "time_lost", "diff": 0.0465,
                      "reference_value": 1.25e-17}])
    assert v["outcomes_moved"] == "time_lost +0.0465 [+0.03, +0.08]"
    (v,) = verdicts([{**base, "metric": "handover_time", "diff": 0.5, "reference_value": 2.0}])
    assert v["outcomes_moved"] == "handover_time +0.5 (+25.0 %) [+0.03, +0.08]"


def test_cell_float_reads_a_cell_as_written_or_as_read_back():
    from handover_eval.closedloop.stats import cell_float

    assert cell_float("0.25") == 0.25 and cell_float(3) == 3.0 and cell_float(0.5) == 0.5
    assert cell_float(True) == 1.0 and cell_float(False) == 0.0
    assert cell_float("inf") == math.inf
    for blank in (None, "", "abc", "nan", math.nan, [1.0]):
        assert math.isnan(cell_float(blank))
