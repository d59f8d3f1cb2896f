"""Simulated participants: independence from the paper's Θ̂, the documented satisfaction,
answers."""

from __future__ import annotations

import ast
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from agents.participants import (
    ISO_LIMITS,
    Body,
    Participant,
    Traits,
    sample_participant,
    sample_population,
)

SOURCE = Path(__file__).resolve().parents[2] / "agents" / "participants.py"
PAPER_THETA_HAT = (114.3, 17.1, 0.14, 7.1)
RANGE_CENTRE = (110.0, 15.0, 12.5)  # K, B, f_r centres (t_f's 0.5 is too common a number to ban)


def test_participant_module_imports_nothing_from_the_env_or_theta() -> None:
    tree = ast.parse(SOURCE.read_text())
    modules = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            modules.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            modules.add(node.module or "")
    assert modules <= {"__future__", "math", "collections.abc", "dataclasses", "numpy"}, modules
    text = SOURCE.read_text()
    for banned in ("HandoverParams", "THETA_RANGES", "handover_env.config", "stiffness", "damping",
                   "forecast_time", "release_force"):
        assert banned not in text, banned
    # and importing it loads no env module
    code = ("import sys, agents.participants; "
            "print(sorted(m for m in sys.modules if m.startswith('handover_env')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=SOURCE.parents[1]).stdout.strip()
    assert out == "[]"


def test_no_theta_hat_or_range_centre_literal() -> None:
    tree = ast.parse(SOURCE.read_text())
    numbers = {
        float(n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant)
        and isinstance(n.value, (int, float))
        and not isinstance(n.value, bool)
    }
    assert not numbers & set(PAPER_THETA_HAT), numbers & set(PAPER_THETA_HAT)
    assert not numbers & set(RANGE_CENTRE), numbers & set(RANGE_CENTRE)
    text = SOURCE.read_text()
    for value in ("114.3", "17.1", "0.14", "7.1"):
        assert not re.search(rf"(?<![\d.]){re.escape(value)}(?![\d])", text), value


def _person(**over) -> Participant:
    traits = {
        "failure_cost": 2.5,
        "unsafe_cost": 1.0,
        "expected_time": 3.0,
        "time_cost": 0.4,
        "slowdown_cost": 0.5,
        "comfort_reach": 0.8,
        "reach_cost": 0.5,
        "arm_time": 1.3,
        "arm_cost": 0.2,
        "preferred_pull": 5.0,
        "pull_cost": 0.4,
        "touch_cost": 0.5,
        "contact_cost": 2.0,
        "jerk_ref": 26.0,
        "jerk_cost": 0.2,
        "answer_noise": 0.3,
        "rating_bias": 0.0,
        "rating_noise": 0.0,
    }
    traits.update(over)
    return Participant(pid=1, body=Body("male", 1.75, 0.85, -0.9), traits=Traits(**traits), seed=0)


PERFECT = {
    "outcome": "success",
    "handover_time": 2.0,
    "handover_time_with_delay": 2.0,
    "time_lost": 0.0,
    "reach_distance": 0.5,
    "arm_extended_time": 1.0,
    "pull_force": 4.0,
    "body_contact_force": 0.0,
    "robot_jerk_rms": 20.0,
}


def test_satisfaction_terms_follow_the_documented_formulas() -> None:
    p = _person()
    assert p.satisfaction(PERFECT) == 5.0
    arm = 0.386 * 1.75
    cases = {
        "failure": (
            {"outcome": "missed", "handover_time": None, "handover_time_with_delay": None},
            2.5,
        ),
        "unsafe": (
            {"outcome": "unsafe_force", "handover_time": None, "handover_time_with_delay": None},
            3.5,
        ),
        "waiting": (
            {"handover_time_with_delay": 5.0, "handover_time": 3.0},
            0.4 * 2.0,
        ),  # lived time counts
        "slowing": ({"time_lost": 0.6}, 0.5 * 0.6),
        "reach": ({"reach_distance": 0.9 * arm}, 0.5 * 1.0),
        "arm_out": ({"arm_extended_time": 3.3}, 0.2 * 2.0),
        "pull": ({"pull_force": 20.0}, 0.4 * 2.0),
        "robot_motion": ({"robot_jerk_rms": 104.0}, 0.2 * 2.0),
    }
    for name, (change, cost) in cases.items():
        assert p.satisfaction({**PERFECT, **change}) == pytest.approx(5.0 - cost), name
    touched = {**PERFECT, "body_contact_force": 70.0, "contact_force_torso": 70.0}
    assert p.satisfaction(touched) == pytest.approx(5.0 - 0.5 - 2.0 * 70.0 / ISO_LIMITS["torso"])
    crushed = {**PERFECT, "body_contact_force": 5000.0, "contact_force_hand_r": 5000.0}
    assert p.satisfaction(crushed) == pytest.approx(
        5.0 - 0.5 - 2.0 * 2.0
    )  # capped at twice the limit


def test_satisfaction_depends_on_the_episode_only() -> None:
    p = _person()
    before = p.satisfaction(PERFECT)
    p.prefers(1.0, 0.0)
    p.likert(PERFECT)
    assert p.satisfaction(PERFECT) == before
    # keys a participant does not judge (e.g. anything about Θ) change nothing
    assert p.satisfaction({**PERFECT, "stiffness": 80.0, "release_force": 20.0}) == before


def test_likert_is_the_rounded_latent_comfort() -> None:
    p = _person()
    assert p.likert(PERFECT) == 5
    assert p.likert({**PERFECT, "pull_force": 5.0 * 2 ** 4}) == 3  # 5 - 1.6 = 3.4
    assert p.likert({**PERFECT, "outcome": "unsafe_force", "pull_force": 5.0 * 2 ** 10}) == 1
    noisy = _person(rating_noise=0.35, rating_bias=0.3)
    ratings = [noisy.likert({**PERFECT, "pull_force": 5.0 * 2 ** 4}) for _ in range(4000)]
    # latent 3.4 + 0.3 = 3.7 with SD 0.35: P(4) = P(3.5 < latent < 4.5)
    expected = norm.cdf((4.5 - 3.7) / 0.35) - norm.cdf((3.5 - 3.7) / 0.35)
    assert np.mean(np.array(ratings) == 4) == pytest.approx(expected, abs=0.03)


def test_preferences_follow_eq2() -> None:
    p = _person(answer_noise=0.4)
    assert p.preference_probability(1.0, 1.0) == pytest.approx(0.5)
    assert p.preference_probability(1.3, 1.0) == pytest.approx(norm.cdf(0.3 / (math.sqrt(2) * 0.4)))
    answers = [p.prefers(1.3, 1.0) for _ in range(5000)]
    assert np.mean(answers) == pytest.approx(p.preference_probability(1.3, 1.0), abs=0.02)


def test_population_is_seeded_and_matches_its_stated_distributions() -> None:
    a, b = sample_population(8, seed=0), sample_population(8, seed=0)
    assert [x.describe() for x in a] == [x.describe() for x in b]
    assert [x.body.sex for x in a].count("male") == 6
    men = [sample_participant(s, "male").body.height for s in range(1500)]
    women = [sample_participant(s, "female").body.height for s in range(1500)]
    assert np.mean(men) == pytest.approx(1.757, abs=0.006) and np.std(men) == pytest.approx(
        0.065, abs=0.006
    )
    assert np.mean(women) == pytest.approx(1.623, abs=0.006)
    people = [sample_participant(s) for s in range(600)]
    pulls = np.array([q.traits.preferred_pull for q in people])
    assert np.median(pulls) == pytest.approx(5.0, rel=0.1)
    speeds = np.array([q.body.speed for q in people])
    assert 0.75 < np.median(speeds) < 0.9
    heights = np.array([q.body.height for q in people])
    assert np.corrcoef(heights, speeds)[0, 1] > 0  # taller people walk faster (dynamic similarity)
    with pytest.raises(ValueError, match="participant seed must be a whole number >= 0"):
        sample_participant(-1)
    with pytest.raises(ValueError, match="need at least one participant"):
        sample_population(0)


def test_walks_drive_the_env_with_the_participants_body() -> None:
    import gymnasium as gym

    import handover_env  # noqa: F401

    p = sample_participant(11)
    opts = p.walk_options("id")
    assert opts["height"] == p.body.height and opts["walker"] == {"pass_y": p.body.pass_y}
    assert set(p.walk_seeds(3, 0)).isdisjoint(p.walk_seeds(3, 1))
    env = gym.make("handover_env/DynamicHandover-v0")
    env.reset(seed=p.walk_seeds(1)[0], options=opts)
    rec = env.unwrapped.receiver
    assert rec.height == pytest.approx(p.body.height)
    assert rec.walker.pass_y == pytest.approx(p.body.pass_y) and rec.walker.speed == pytest.approx(
        p.body.speed
    )
    env.close()
