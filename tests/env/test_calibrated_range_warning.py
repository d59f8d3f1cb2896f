"""A walker outside the walks the person was calibrated on: one warning per env naming the field
and the range, ``info["within_calibration"]`` at reset and at every step, nothing refused."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401 - registers the envs
from handover_env.person.calibrated_range import CALIBRATED_RANGE
from handover_env.person.walk_range import walk_check


def _reset(env, **options):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _, info = env.reset(seed=options.pop("seed", 0), options=options)
    return info, [str(w.message) for w in caught if issubclass(w.category, UserWarning)]


def test_a_fast_walker_is_warned_once_and_flagged_at_every_step() -> None:
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    info, said = _reset(env, receiver="id", seed=0)
    assert info["within_calibration"] is True and not said
    info, said = _reset(env, receiver="id", seed=1, speed=2.0)
    assert info["within_calibration"] is False
    assert len(said) == 1
    lo, hi = CALIBRATED_RANGE.speed
    assert "(speed)" in said[0] and f"[{lo:.2f}, {hi:.2f}]" in said[0]
    assert "seed 1" in said[0] and "calibrated_range.md" in said[0]
    for _ in range(5):  # simulated all the same, flagged at every step
        _, _, term, _, info = env.step(np.array([0.4, 0.3, 1.0, 0.0]))
        assert info["within_calibration"] is False
        if term:
            break
    info, said = _reset(env, receiver="id", seed=2, speed=2.2)  # once per env
    assert info["within_calibration"] is False and not said
    info, _ = _reset(env, receiver="id", seed=0)
    assert info["within_calibration"] is True
    env.close()


def test_every_field_is_checked_and_a_new_env_warns_again() -> None:
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    info, said = _reset(env, receiver="ood", seed=3, height=2.0)
    assert info["within_calibration"] is False and len(said) == 1 and "(height)" in said[0]
    assert "height" in [f for f, _, _ in env.receiver.calibration.outside]
    fields = env.receiver.calibration.fields
    assert set(fields) == {"speed", "height", "pass_distance", "pause"}
    assert fields["height"] == pytest.approx(2.0)
    env.close()
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    info, said = _reset(env, receiver="id", seed=5, speed=0.3)
    assert info["within_calibration"] is False and len(said) == 1 and "(speed)" in said[0]
    env.close()


def test_the_walk_is_measured_before_a_static_stop() -> None:
    """The static handover's stop is the task's, not a pause of the walker's own."""
    env = gym.make("handover_env/StaticHandover-v0").unwrapped
    info, said = _reset(env, receiver="id", seed=0)
    assert info["within_calibration"] is True and not said
    assert env.receiver.calibration.fields["pause"] == 0.0
    check = walk_check(env.receiver.motion, "id")
    assert check.fields["pause"] > 0.5  # the stopped motion itself would read as a long pause
    env.close()
