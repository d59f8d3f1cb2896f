"""The simulated person's decisions for any walk (issue 23): left behind, meeting, take distance.

Pure functions of the person's remaining path (handover_env.person.receiver_rules) on walks
built here: straight, pausing, turning back; plus the same rules run on synthetic recordings by
the calibration analysis (handover_eval.calibration.decisions).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from handover_env.person.receiver_rules import (
    MIN_TAKE,
    TAKE_CLOSEST,
    TAKE_INTERCEPT,
    PathAhead,
    closest_approach,
    left_behind,
    meet,
    take_distance,
)
from handover_eval.calibration.decisions import reach_fit, rule_check

RATE = 30.0
BEHIND, WITHIN = 0.35, 1.2
REACH, COMFORT = 0.70, 0.64


def _path(xs: np.ndarray, y: float = -0.8, z: float = 1.45) -> PathAhead:
    """A shoulder path along x (frames at 30 Hz), facing the way it moves (-x if still)."""
    xs = np.asarray(xs, dtype=np.float64)
    step = np.gradient(xs)
    sign = np.where(step > 1e-9, 1.0, -1.0)
    # a paused person keeps the heading they had
    for i in range(1, sign.size):
        if abs(step[i]) <= 1e-9:
            sign[i] = sign[i - 1]
    forward = np.column_stack([sign, np.zeros_like(xs), np.zeros_like(xs)])
    shoulder = np.column_stack([xs, np.full_like(xs, y), np.full_like(xs, z)])
    return PathAhead(np.arange(xs.size) / RATE, shoulder, forward)


def _walk(x0: float, x1: float, speed: float = 0.9) -> np.ndarray:
    n = int(round(abs(x1 - x0) / speed * RATE))
    return np.linspace(x0, x1, n + 1)[1:]


OBJ = np.array([0.5, -0.45, 1.30])  # 0.35 m to the right of a path at y = -0.8


def test_a_straight_walker_leaves_an_object_behind_only_once_past_it():
    ahead = _path(np.concatenate([[1.0], _walk(1.0, -1.0)]))
    assert not left_behind(OBJ, ahead, BEHIND, WITHIN)  # still in front
    past = _path(np.concatenate([[0.0], _walk(0.0, -1.0)]))  # 0.5 m past it, walking away
    assert left_behind(OBJ, past, BEHIND, WITHIN)
    just = _path(np.concatenate([[0.3], _walk(0.3, -1.0)]))  # 0.2 m past: not yet
    assert not left_behind(OBJ, just, BEHIND, WITHIN)
    far = _path(np.concatenate([[-1.5], _walk(-1.5, -2.5)]))  # far beyond PASS_DISTANCE
    assert not left_behind(OBJ, far, BEHIND, WITHIN)


def test_a_person_who_turns_back_has_not_left_it_behind():
    # 0.5 m past the object, walks back 1.0 m toward +x, then on toward -x again
    xs = np.concatenate([[0.0], _walk(0.0, 1.0), _walk(1.0, -1.0)])
    assert not left_behind(OBJ, _path(xs), BEHIND, WITHIN)
    # ... and once the last pass is over, it is left behind
    after = xs[xs.size - 20:]
    assert after[0] < OBJ[0] - BEHIND and left_behind(OBJ, _path(after), BEHIND, WITHIN)


def test_a_person_who_pauses_past_it_then_turns_back_has_not_left_it_behind():
    xs = np.concatenate([[0.0], np.full(45, 0.0), _walk(0.0, 0.9), _walk(0.9, -1.0)])
    assert not left_behind(OBJ, _path(xs), BEHIND, WITHIN)


def test_the_meeting_waits_for_a_pause():
    straight = _path(np.concatenate([[1.6], _walk(1.6, -1.0)]))
    paused = _path(np.concatenate([[1.6], _walk(1.6, 1.2), np.full(30, 1.2), _walk(1.2, -1.0)]))
    still = np.zeros(3)
    a = meet(OBJ, still, straight, REACH, 0.63, COMFORT)
    b = meet(OBJ, still, paused, REACH, 0.63, COMFORT)
    assert a.reachable and b.reachable and a.take == pytest.approx(b.take, abs=0.005)
    # the take distance is reached 0.7 m before the object: 1.6 - 0.5 - ~0.4 along the walk
    assert b.time == pytest.approx(a.time + 1.0, abs=2 / RATE)  # the 30-frame (1 s) pause
    assert a.distance <= a.take + 0.03


def test_the_reach_grows_with_how_far_the_object_is_held_from_the_path():
    path = _path(np.concatenate([[1.6], _walk(1.6, -1.0)]))
    near = np.array([0.5, -0.65, 1.40])  # 0.15 m to the side, 5 cm below the shoulder
    far = np.array([0.5, -0.30, 1.35])  # 0.5 m to the side
    assert closest_approach(near, path) == pytest.approx(math.hypot(0.15, 0.05), abs=0.01)
    assert closest_approach(far, path) == pytest.approx(math.hypot(0.50, 0.10), abs=0.01)
    m_near = meet(near, np.zeros(3), path, REACH, 0.63, COMFORT)
    m_far = meet(far, np.zeros(3), path, REACH, 0.63, COMFORT)
    assert m_near.take == pytest.approx(TAKE_INTERCEPT + TAKE_CLOSEST * m_near.closest)
    assert m_far.take == pytest.approx(TAKE_INTERCEPT + TAKE_CLOSEST * m_far.closest)
    assert m_far.take - m_near.take == pytest.approx(TAKE_CLOSEST * 0.35, abs=0.01)
    # the person takes the far object farther from the shoulder (not at full extension either)
    assert m_far.distance > m_near.distance + 0.07 and m_far.distance < COMFORT
    # the take distance stays within the person's comfortable reach and above MIN_TAKE
    assert take_distance(5.0, COMFORT) == COMFORT and take_distance(-5.0, COMFORT) == MIN_TAKE


def test_an_object_beyond_reach_is_not_met():
    path = _path(np.concatenate([[1.6], _walk(1.6, -1.0)]))
    m = meet(np.array([0.5, 0.3, 1.3]), np.zeros(3), path, REACH, 0.63, COMFORT)  # 1.1 m aside
    assert not m.reachable and m.distance == pytest.approx(math.hypot(1.1, 0.15), abs=0.01)


def test_path_ahead_rejects_bad_shapes():
    with pytest.raises(ValueError, match="PathAhead"):
        PathAhead(np.zeros(3), np.zeros((3, 3)), np.zeros((2, 3)))


def test_rule_check_and_reach_fit():
    rows = [{"old_left_behind": -2.0, "left_behind": math.nan},
            {"old_left_behind": math.nan, "left_behind": math.nan}]
    c = rule_check(rows)
    assert c == {"recordings": 2, "old_left_behind_count": 1, "old_left_behind_earliest": -2.0,
                 "left_behind_count": 0, "left_behind_earliest": None}
    rng = np.random.default_rng(0)
    x = rng.uniform(0.1, 0.7, 400)
    y = 0.4 + 0.25 * x + rng.normal(0, 0.02, 400)
    f = reach_fit(x, y)
    assert f["ls_b"] == pytest.approx(0.25, abs=0.02) and f["ls_a"] == pytest.approx(0.4, abs=0.01)
    assert abs(f["rma_b"]) >= abs(f["ls_b"]) and f["r"] > 0.9
    assert reach_fit(np.ones(2), np.ones(2)) == {"n": 2}
