"""The simulated person under physics: outcomes that cannot lie, contact, effort, replays."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401
from agents.base import Agent
from agents.giver_replay import GiverReplayAgent
from agents.null import DelayedAgent, NullAgent
from agents.reactive import ReactiveAgent
from handover_env.person import trajectory
from handover_env.person.gait import walking_pose
from handover_env.person.person import RATE
from handover_env.person.skeleton import BodyDims, joints_of

ENV_ID = "handover_env/DynamicHandover-v0"
DATA = (
    Path(__file__).resolve().parents[3]
    / "shared"
    / "data"
    / "dynamic_handover_dataset"
    / "whole_motions"
)


def _run(env, agent, seed=0, options=None):
    obs, info = env.reset(seed=seed, options=options or {"receiver": "id"})
    agent.reset()
    while True:
        obs, _, term, trunc, info = env.step(agent.act(obs))
        if term or trunc:
            return info, term, trunc


class _Hold:
    """Holds the object at a fixed target."""

    def __init__(self, target):
        self.target = np.asarray(target, dtype=np.float32)

    def reset(self):
        pass

    def act(self, obs):
        return self.target.copy()


def _straight_walk(y: float, speed: float = 0.9, start_x: float = 2.2, frames: int = 150,
                   skeleton: bool = False) -> dict:
    """A replay dict of a person walking along y toward -x (optionally with a full skeleton)."""
    t = np.arange(frames) / RATE
    xy = np.stack([start_x - speed * t, np.full_like(t, y)], axis=1)
    episode = {"receiver_xy": xy, "source_id": f"straight_{y}"}
    if skeleton:
        heading = np.full(frames, math.pi)
        phase = np.mod(2 * math.pi * speed * t / (2 * 0.28 * 1.725), 2 * math.pi)
        traj = trajectory.BaseTrajectory(t=t, xy=xy, heading=heading, gait_phase=phase)
        dims = BodyDims.from_height(1.725)
        episode["receiver_pose"] = joints_of(walking_pose(traj, dims), dims)
    return episode


@pytest.fixture(scope="module")
def env():
    # the person is tested in the exact world, so that the sensors (issue 24) do not decide an
    # outcome; sensing="paper" is tested in tests/env/test_sensing_env.py
    e = gym.make(ENV_ID, sensing="ideal")
    yield e
    e.close()


def test_a_handover_grasps_before_the_release_without_ghosts(env):
    for seed in (0, 1):
        info, _term, _ = _run(env, ReactiveAgent(), seed)
        assert info["outcome"] == "success"
        assert info["transfer_time"] < info["release_time"]  # the hand held it first
        assert info["penetration"] < 0.01
        assert 0.3 < info["reach_distance"] < 0.75 and info["arm_extended_time"] > 0.3
        assert info["release_force"] > 7.1 and info["pull_force"] >= info["release_force"] * 0.5


def test_a_bump_that_opens_the_gripper_is_a_premature_release_not_a_success(env):
    """The robot holds the bottle in front of the left side of the chest of a person whose
    (replayed, recorded-mode) right hand never comes near it: the torso runs into the gripper and
    the push opens it before any grasp."""
    y = -0.75
    episode = _straight_walk(y, skeleton=True)
    info, term, _ = _run(
        env,
        _Hold([0.5, y - 0.08, 1.25, -math.pi / 2]),
        options={"receiver": "replay", "episode": episode, "hand_mode": "recorded"},
    )
    assert term and info["outcome"] == "premature_release" and not info["is_success"]
    assert info["released"] and info["transfer_time"] is None
    assert (info["body_contact_object"] or info["body_contact_robot"]) and info[
        "contact_force_torso"
    ] > 7.1


def test_an_object_out_of_reach_slows_the_person_then_is_missed(env):
    """The robot keeps the object at its ready pose; the person passes 1.3 m away: too far to
    take it, so they slow down (as far as the recordings show) and walk past."""
    info, term, _ = _run(
        env, NullAgent(), options={"receiver": "replay", "episode": _straight_walk(-1.3)}
    )
    assert term and info["outcome"] == "missed"
    assert info["min_speed_factor"] == pytest.approx(0.82)
    assert info["time_lost"] > 0.05
    assert info["transfer_time"] is None and not info["released"]


def test_the_null_agent_makes_the_handover_slower_than_the_reactive_one(env):
    """Holding the object still, the robot leaves the person to come and take it: it happens, later.
    (The time tells them apart, by 0.3-0.9 s on the seeds 0-7 where both succeed; on seed 3 the
    walker, whose own reach offset is -0.05 m, leaves the still object behind: ``missed``.)"""
    info = {}
    for name, agent in (("reactive", ReactiveAgent()), ("null", NullAgent())):
        info[name], *_ = _run(env, agent, seed=4)
        assert info[name]["outcome"] == "success", (name, info[name]["outcome"])
    assert info["null"]["handover_time"] > info["reactive"]["handover_time"] + 0.3
    assert info["null"]["transfer_time"] > info["reactive"]["transfer_time"]


class _Counting(Agent):
    """Action k (from 0 since ``reset``) is ``(k, 0, 0, 0)``; a prediction's rows hold the number
    of history frames it was given and that history's last x."""

    horizon = 4

    def __init__(self) -> None:
        self.k = 0

    def reset(self) -> None:
        self.k = 0

    def act(self, obs):
        self.k += 1
        return np.array([self.k - 1, 0.0, 0.0, 0.0], dtype=np.float32)

    def predict(self, receiver_history):
        hist = np.asarray(receiver_history, dtype=np.float64)
        return np.tile([hist.shape[0], hist[-1, 0], 0.0], (self.horizon, 1))


def test_a_delayed_agent_acts_half_a_second_late():
    agent = DelayedAgent(_Counting(), delay=0.5)
    assert agent.steps == 15 and agent.horizon == 4
    obs = np.zeros(ReactiveAgent().layout.size, dtype=np.float32)
    for _episode in range(2):  # reset forgets the queue of the previous episode
        agent.reset()
        actions = np.array([agent.act(obs) for _ in range(40)])
        # every action: the ready pose for 15 steps, then the wrapped agent's action k - 15
        wanted = np.array(
            [agent.ready if k < 15 else [k - 15, 0.0, 0.0, 0.0] for k in range(40)],
            dtype=np.float32,
        )
        np.testing.assert_array_equal(actions, wanted)
    np.testing.assert_allclose(agent.ready, (0.3, -0.4, 1.15, -math.pi / 2), rtol=1e-7)
    # open loop: the prediction from the track as it was 15 frames ago (its first frame at least)
    track = np.column_stack([np.arange(40.0), np.zeros(40)])
    for t in (1, 10, 15, 16, 17, 40):
        np.testing.assert_array_equal(
            agent.predict(track[:t]), np.tile([max(1, t - 15), max(0, t - 16), 0.0], (4, 1)))
    # no delay passes every action straight through
    now = DelayedAgent(_Counting(), delay=0.0)
    now.reset()
    assert [float(now.act(obs)[0]) for _ in range(3)] == [0.0, 1.0, 2.0]
    assert DelayedAgent(_Counting(), delay=0.1).steps == 3
    with pytest.raises(ValueError, match="delay"):
        DelayedAgent(ReactiveAgent(), delay=-1.0)


def test_replay_without_a_skeleton_walks_the_track_with_a_scripted_gait():
    env = gym.make(ENV_ID, sensing="ideal")  # the exact camera
    episode = _straight_walk(-0.9)
    info, _term, _ = _run(env, ReactiveAgent(), options={"receiver": "replay", "episode": episode})
    assert info["outcome"] == "success"
    # The camera saw the recorded track.
    u = env.unwrapped
    np.testing.assert_allclose(u._frames_buf[0], episode["receiver_xy"][0], atol=1e-12)


def test_person_settings_and_bad_options():
    with pytest.raises(ValueError, match="unknown person setting"):
        gym.make(ENV_ID, person={"reach_time": 1.0})
    with pytest.raises(ValueError, match="min_speed_factor"):
        gym.make(ENV_ID, person={"min_speed_factor": 0.0})
    e = gym.make(ENV_ID, person={"reach_duration": 0.9})
    assert e.unwrapped.receiver.config.reach_duration == 0.9
    with pytest.raises(ValueError, match="recorded"):
        e.reset(seed=0, options={"receiver": "id", "hand_mode": "recorded"})
    with pytest.raises(RuntimeError, match="reset"):
        e.step(e.action_space.sample())  # the failed reset left it un-reset
    with pytest.raises(ValueError, match="skeleton"):
        e.reset(
            seed=0,
            options={
                "receiver": "replay",
                "episode": _straight_walk(-0.9),
                "hand_mode": "recorded",
            },
        )


def test_same_seed_same_person_and_outcome():
    a, b = gym.make(ENV_ID), gym.make(ENV_ID)
    ia, *_ = _run(a, ReactiveAgent(), seed=5, options={"receiver": "ood"})
    ib, *_ = _run(b, ReactiveAgent(), seed=5, options={"receiver": "ood"})
    assert ia == ib


@pytest.mark.skipif(not DATA.is_dir(), reason="development copy of the public dataset not present")
def test_giver_replay_takes_the_object_where_the_recorded_person_did(env):
    """On held-out recordings (Table I folds 5-9: not used to calibrate the person) the robot that
    moves the object along the recorded giver's path hands it over at the recorded time."""
    _giver_replay_on_held_out(env)


@pytest.mark.skipif(not DATA.is_dir(), reason="development copy of the public dataset not present")
def test_giver_replay_hands_over_with_the_papers_sensors_and_speed_limit_too():
    """The same on the paper profile: the camera, the imperfectly compensated wrist F/T and the
    UR5e's 180 deg/s joint limit, met by speed scaling (before it, 7 of these 8 released early)."""
    e = gym.make(ENV_ID, sensing="paper")
    try:
        _giver_replay_on_held_out(e)
    finally:
        e.close()


def _giver_replay_on_held_out(env) -> None:
    from handover_env.data.dataset import stratified_fold_ids
    from handover_env.data.detect import detect_transfer
    from handover_env.data.filtering import smooth_track
    from handover_env.data.public import list_public_files
    from handover_env.person.recording import load_recording

    files = list_public_files(DATA)
    folds = stratified_fold_ids(
        np.array([p.name.startswith("motion_variation") for p in files]), 10, 0
    )
    held_out = [p for p, f in zip(files, folds) if f >= 5][:8]
    agent = GiverReplayAgent()
    ok, dts = 0, []
    for path in held_out:
        rec = load_recording(path)
        agent.set_episode(rec.episode)
        info, *_ = _run(env, agent, options={"receiver": "replay", "episode": rec})
        ok += info["outcome"] == "success"
        det = detect_transfer(
            smooth_track(rec.receiver_pose, 30.0), smooth_track(rec.episode.giver_xyz, 30.0)
        )
        if det.frame is not None and info["transfer_time"] is not None:
            dts.append(abs(info["transfer_time"] - det.frame / 30.0))
        assert info["penetration"] < 0.01
    assert ok >= 7
    assert np.median(dts) <= 0.25


@pytest.mark.skipif(not DATA.is_dir(), reason="development copy of the public dataset not present")
def test_a_recorded_person_stops_on_the_static_stop_line():
    from agents.static import StaticAgent
    from handover_env.envs.static_handover_v0 import STOP_XY
    from handover_env.person.recording import load_recording

    env = gym.make("handover_env/StaticHandover-v0")
    rec = load_recording(DATA / "motion_normal_0.pkl")
    info, _term, _ = _run(env, StaticAgent(), options={"receiver": "replay", "episode": rec})
    u = env.unwrapped
    assert info["outcome"] == "success"
    assert u.receiver.at_rest and abs(u.receiver.base()[0] - STOP_XY[0]) < 0.05
    assert info["arm_extended_time"] > 2.0  # the raised hand waited for detection and delivery


class _Timed:
    """Holds the object at ``first`` until ``t`` s, then at ``then``."""

    def __init__(self, first, then, t):
        self.first, self.then, self.t = (np.asarray(v, dtype=np.float32) for v in (first, then, t))
        self.n = 0

    def reset(self):
        self.n = 0

    def act(self, obs):
        self.n += 1
        return (self.first if self.n / RATE < self.t else self.then).copy()


def _segment(x0: float, x1: float, speed: float = 0.9) -> np.ndarray:
    n = int(round(abs(x1 - x0) / speed * RATE))
    return np.linspace(x0, x1, n + 1)[1:]


def test_a_person_who_walks_past_pauses_and_turns_back_still_takes_the_object(env):
    """Issue 23: the person walks 0.5 m past where the object will be, pauses 1 s, walks back 1 m
    and then on. The object is presented at 2.0 s, while they stand 0.5 m past it (more than
    give_up_behind behind their shoulder, within PASS_DISTANCE: the former rule called that a
    miss). Their own walk brings it ahead of them again, so they wait and take it on the way."""
    xs = np.concatenate([[2.0], _segment(2.0, 0.0), np.full(30, 0.0), _segment(0.0, 1.0, 0.6),
                         _segment(1.0, -1.5)])
    episode = {"receiver_xy": np.column_stack([xs, np.full_like(xs, -0.8)]),
               "source_id": "turn_back"}
    agent = _Timed([0.5, 0.0, 1.25, -math.pi / 2], [0.5, -0.45, 1.25, -math.pi / 2], 2.0)
    obs, info = env.reset(seed=0, options={"receiver": "replay", "episode": episode})
    agent.reset()
    states = []
    while True:
        obs, _, term, trunc, info = env.step(agent.act(obs))
        states.append(env.unwrapped.receiver.state)
        if term or trunc:
            break
    assert info["outcome"] == "success" and "passed" not in states
    paused = (np.flatnonzero(np.diff(xs) > 0)[0] + 1) / RATE  # the pause ends here (3.2 s)
    turned = (np.flatnonzero(np.diff(xs) > 0)[-1] + 1) / RATE  # the walk back ends here (4.9 s)
    # the reach starts on the way back, ahead of the meeting on the last pass, and the hand takes
    # the object only on that pass
    assert info["reach_onset_time"] > paused and info["transfer_time"] > turned
    # shoulder to object at the grasp (0.27 m: the person takes the bottle's lower part while
    # standing close on the way back)
    assert 0.25 < info["reach_distance"] < 0.65


def test_reach_distance_is_the_shoulder_object_distance_at_the_grasp_and_grows_with_the_offset(
    env,
):
    """``reach_distance`` is measured as for the recordings (shoulder to the object's centre at
    the grasp), and the person reaches farther for an object held farther from their path (the
    take distance, planned to the grasp point on the bottle's lower part, grows by 0.25 x the
    closest approach; the shoulder-centre distance measured here by 4 cm over these 0.3 m)."""
    reach = {}
    for side in (0.15, 0.45):
        y = -0.8
        episode = _straight_walk(y)
        info, _, _ = _run(env, _Hold([0.5, y + side, 1.25, -math.pi / 2]),
                          options={"receiver": "replay", "episode": episode})
        assert info["outcome"] == "success"
        reach[side] = info["reach_distance"]
    assert 0.3 < reach[0.15] < reach[0.45] - 0.03 and reach[0.45] < 0.7
