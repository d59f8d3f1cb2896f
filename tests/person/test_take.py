"""The person's own reach offset: drawn with the seed for a scripted walker, the recorded person's
own for a replayed recording, added to the giver-dependent part of the take distance."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from synthetic_skeletons import write_folder

import handover_env  # noqa: F401 - registers the envs
from handover_env.person.person import scripted_motion
from handover_env.person.reach_offset import REACH_OFFSET
from handover_env.person.receiver_rules import (
    MIN_TAKE,
    TAKE_CLOSEST,
    TAKE_INTERCEPT,
    PathAhead,
    meet,
    take_distance,
)
from handover_env.person.recording import load_recording
from handover_env.person.take import person_offset, recorded_offset

REAL = Path("/work/shared/data/dynamic_handover_dataset/whole_motions")


def test_take_distance_is_the_giver_part_plus_the_offset() -> None:
    line = TAKE_INTERCEPT + TAKE_CLOSEST * 0.4
    assert take_distance(0.4, 1.0, 0.07) == pytest.approx(line + 0.07, abs=1e-15)
    assert take_distance(0.4, 1.0) == pytest.approx(line, abs=1e-15)
    assert take_distance(0.4, 1.0, -1.0) == MIN_TAKE and take_distance(0.4, 0.6, 0.5) == 0.6
    # meet() uses the same take distance: a person with a longer reach takes it farther out
    n = 60
    path = PathAhead(np.arange(n) / 30.0,
                     np.column_stack([np.linspace(-2, 2, n), np.zeros(n), np.full(n, 1.4)]),
                     np.tile([1.0, 0.0, 0.0], (n, 1)))
    obj = np.array([1.0, -0.3, 1.2])
    short = meet(obj, np.zeros(3), path, 0.9, 0.63, 0.9, offset=-0.1)
    far = meet(obj, np.zeros(3), path, 0.9, 0.63, 0.9, offset=0.1)
    assert far.take - short.take == pytest.approx(0.2, abs=1e-12)
    assert far.time < short.time


def test_a_scripted_walker_draws_its_offset_after_its_walk() -> None:
    env = gym.make("handover_env/DynamicHandover-v0", person={"reach_offset": True}).unwrapped
    offsets = []
    for seed in range(6):
        _, info = env.reset(seed=seed, options={"receiver": "id"})
        rng = np.random.default_rng(seed)
        walk = scripted_motion(rng, "id")
        # the walk of a seed is the one drawn without an offset; the offset is the next draw
        np.testing.assert_array_equal(env.receiver.motion.camera_xy, walk.camera_xy)
        assert info["reach_offset"] == REACH_OFFSET.draw(rng)
        assert env.receiver.reach_offset.origin == "drawn"
        offsets.append(info["reach_offset"])
    _, again = env.reset(seed=3, options={"receiver": "id"})
    assert again["reach_offset"] == offsets[3]
    assert len(set(offsets)) == len(offsets)
    lo, hi = REACH_OFFSET.quantiles[0][1], REACH_OFFSET.quantiles[-1][1]
    assert all(lo <= o <= hi for o in offsets)
    env.close()


def test_a_replayed_recording_carries_its_own_offset(tmp_path: Path) -> None:
    from handover_eval.calibration.report import analyse_file

    folder = write_folder(tmp_path / "whole_motions", n=8)
    env = gym.make("handover_env/DynamicHandover-v0", person={"reach_offset": True}).unwrapped
    own = 0
    for path in sorted(folder.glob("*.pkl")):
        rec = load_recording(path)
        m = analyse_file(path).analysis.measures
        expected = m["object_shoulder_transfer"] - (
            TAKE_INTERCEPT + TAKE_CLOSEST * m["path_closest_onset"])
        got = recorded_offset(rec)
        if not np.isfinite(expected):
            assert got is None
            continue
        assert got == pytest.approx(expected, abs=1e-9)
        _, info = env.reset(seed=0, options={"receiver": "replay", "episode": rec})
        assert info["reach_offset"] == got and env.receiver.reach_offset.origin == "recorded"
        own += 1
    assert own >= 4
    # a pelvis track alone has no recorded reach: the replayed person draws one
    drawn = person_offset(np.random.default_rng(1), "replay", rec.episode)
    assert drawn.origin == "drawn"
    assert drawn.value == REACH_OFFSET.draw(np.random.default_rng(1))
    env.close()


def test_the_offset_is_on_by_default_and_can_be_switched_off() -> None:
    """On by default: each scripted walker draws its own offset with its seed. Switched off,
    nothing is drawn (the walk and everything after it are as without the setting) and the
    offset is 0."""
    plain = gym.make("handover_env/DynamicHandover-v0", person={"reach_offset": False}).unwrapped
    _, info = plain.reset(seed=4, options={"receiver": "id"})
    assert info["reach_offset"] == 0.0 and plain.receiver.reach_offset.origin == "off"
    assert plain.receiver.config.reach_offset is False
    after_plain = plain.np_random.random()
    default = gym.make("handover_env/DynamicHandover-v0").unwrapped
    assert default.receiver.config.reach_offset is True
    _, info = default.reset(seed=4, options={"receiver": "id"})
    assert default.receiver.reach_offset.origin == "drawn" and info["reach_offset"] != 0.0
    assert default.np_random.random() != after_plain  # the draw moves the stream on
    plain.close()
    default.close()
    with pytest.raises(ValueError, match="reach_offset must be True or False"):
        gym.make("handover_env/DynamicHandover-v0", person={"reach_offset": "yes"})


@pytest.mark.skipif(not REAL.is_dir(), reason="the development copy of the dataset is absent")
def test_recorded_offsets_on_the_development_copy() -> None:
    """The replay's own offset is the residual the offsets' distribution is made of."""
    from handover_env.data.public import list_public_files
    from handover_eval.calibration.report import analyse_file

    files = list_public_files(REAL)
    compared = 0
    for path in files[:12] + [p for p in files if p.name.startswith("motion_variation_")][:4]:
        m = analyse_file(path).analysis.measures
        expected = m["object_shoulder_transfer"] - (
            TAKE_INTERCEPT + TAKE_CLOSEST * m["path_closest_onset"])
        got = recorded_offset(load_recording(path))
        if np.isfinite(expected):
            assert got == pytest.approx(expected, abs=1e-9)
            compared += 1
        else:
            assert got is None
    assert compared >= 12
