"""The robot the paper had, in the env (issue 24): sensing profiles, camera, wrist F/T, controller.

Numbers asserted come from docs/sensing.md (the datasheet precision, the camera latency, the
constant M); the exact world is the "ideal" profile.
"""

from __future__ import annotations

import json
import math
import pickle

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent
from handover_env.envs.base_handover import READY_POS, READY_YAW
from handover_env.sensors import make_profile
from handover_env.sensors.profiles import CAMERA_FIELDS, CONTROLLER_FIELDS, WRIST_FIELDS

DYN = "handover_env/DynamicHandover-v0"
STAT = "handover_env/StaticHandover-v0"
READY_ACTION = np.array([*READY_POS, READY_YAW], dtype=np.float32)


def _record_ticks(env, fn):
    """Call ``fn(u)`` after every 200 Hz tick of ``env``; returns the list of its values."""
    u = env.unwrapped
    tick, rows = u._tick, []

    def recording_tick() -> None:
        tick()
        rows.append(fn(u))

    u._tick = recording_tick
    return rows


def _episode(env, seed, receiver="id", agent=None, steps=600):
    agent = agent or ReactiveAgent()
    agent.reset()
    obs, info0 = env.reset(seed=seed, options={"receiver": receiver})
    out = [obs]
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(agent.act(obs))
        out.append(obs)
        if term or trunc:
            break
    return info0, info, np.array(out)


def test_paper_is_the_default_and_info_reports_the_profile():
    env = gym.make(DYN)
    obs, info = env.reset(seed=0)
    assert info["sensing"] == "paper" and env.unwrapped.sensor_profile == make_profile("paper")
    params = info["sensing_params"]
    assert params["camera"]["latency"] == 0.1 and params["wrist"]["precision"] == 3.5
    assert params["controller"]["inertia"] == 4.7
    json.dumps(params)  # JSON-serialisable
    _, info, _ = env.step(READY_ACTION)[0], env.step(READY_ACTION)[-1], None
    assert info["sensing"] == "paper" and "sensing_params" not in info
    u = env.unwrapped
    assert u.controller.config.mode == "constant_m" and u.controller.config.inertia == 4.7
    assert u.controller.config.joint_speed_limit == pytest.approx(math.pi)
    assert u.controller.config.max_linear_speed == 1.0  # the datasheet TCP speed
    assert u.wrist.ft is not None and u.camera_model.delay_frames == 3
    ideal = gym.make(DYN, sensing="ideal").unwrapped
    ideal.reset(seed=0)
    assert ideal.controller.config.mode == "lambda" and ideal.wrist.ft is None
    assert ideal._cmd_delay == 0.0 and ideal.camera_model.delay_frames == 0


def test_ideal_camera_sees_the_truth_and_the_paper_camera_is_late_and_noisy():
    for sensing in ("ideal", "paper"):
        env = gym.make(DYN, sensing=sensing)
        u = env.unwrapped
        obs, _ = env.reset(seed=3)
        true_xy, seen_xy, seen_n = [], [], []
        for _ in range(40):
            true_xy.append(u.receiver.camera_xy().copy())
            parts = u.layout.unflatten(obs)
            seen_xy.append(parts["receiver_xy_history"][-1])
            seen_n.append(parts["receiver_frames_seen"][0])
            obs, _, term, trunc, _ = env.step(READY_ACTION)
            if term or trunc:
                break
        true_xy, seen_xy = np.array(true_xy), np.array(seen_xy)
        if sensing == "ideal":
            np.testing.assert_allclose(seen_xy, true_xy, atol=1e-6)  # float32 of the truth
            assert seen_n[:3] == [1, 2, 3]
        else:
            assert seen_n[:4] == [0, 0, 0, 1]  # 100 ms = 3 frames before the first delivery
            err = seen_xy[3:] - true_xy[:-3]  # frame k delivered at k + 3
            assert 0.002 < float(np.std(err)) < 0.012  # the 5.1 mm pelvis noise


def test_obs_noise_and_obs_latency_are_camera_overrides():
    env = gym.make(DYN, sensing="ideal", obs_latency=2, obs_noise=0.01)
    u = env.unwrapped
    assert u.sensor_profile.camera.latency == pytest.approx(2 / 30)
    assert u.sensor_profile.camera.pelvis_sigma == 0.01 == u.sensor_profile.camera.hand_sigma
    env.reset(seed=0)
    assert u.camera_model.delay_frames == 2
    with pytest.raises(ValueError, match="given both"):
        gym.make(DYN, obs_latency=2, sensors={"camera": {"latency": 0.05}})
    with pytest.raises(ValueError, match="obs_latency must be a whole number"):
        gym.make(DYN, obs_latency=1.5)
    with pytest.raises(ValueError, match="camera latency must be in"):
        gym.make(DYN, obs_latency=30)


def test_bad_sensing_settings_are_refused_naming_the_field():
    with pytest.raises(ValueError, match="sensing must be one of"):
        gym.make(DYN, sensing="real")
    with pytest.raises(ValueError, match=r"unknown wrist field\(s\) \['noise'\]"):
        gym.make(DYN, sensors={"wrist": {"noise": 1.0}})
    with pytest.raises(ValueError, match="controller inertia must be in"):
        gym.make(DYN, sensors={"controller": {"inertia": -1.0}})
    with pytest.raises(ValueError, match="camera rate_hz must be the env's 30 Hz"):
        gym.make(DYN, sensors={"camera": {"rate_hz": 60.0}})
    with pytest.raises(ValueError, match="control_rate_hz must divide"):
        gym.make(DYN, sensors={"controller": {"control_rate_hz": 250.0}})


#: Every numeric sensor override field, then the env's three older sensing kwargs: each is one
#: case in which an integer too large for a float (``10**400``) must be one error naming it.
_HUGE_CASES = [
    ({"sensors": {group: {name: None}}}, rf"{group} {name} must be finite and in \[")
    for group, table in (("camera", CAMERA_FIELDS), ("wrist", WRIST_FIELDS),
                         ("controller", CONTROLLER_FIELDS))
    for name in table
] + [
    ({"obs_noise": None}, r"obs_noise must be a finite number >= 0 \(m\)"),
    ({"obs_latency": None}, r"obs_latency must be a whole number of frames >= 0"),
    ({"force_filter_tau": None},
     r"force_filter_tau \(the wrist filter_tau\): wrist filter_tau must be finite"),
]


def _with(kwargs: dict, value: object) -> dict:
    """``kwargs`` with its one ``None`` leaf replaced by ``value``."""
    if "sensors" in kwargs:
        ((group, fields),) = kwargs["sensors"].items()
        return {"sensors": {group: {name: value for name in fields}}}
    return {key: value for key in kwargs}


def test_every_sensing_number_is_one_of_the_23_cases():
    assert len(_HUGE_CASES) == 23 == len(CAMERA_FIELDS) + len(WRIST_FIELDS) + len(
        CONTROLLER_FIELDS) + 3


@pytest.mark.parametrize(("kwargs", "message"), _HUGE_CASES,
                         ids=[m.split(" must")[0].replace(" ", ".") for _, m in _HUGE_CASES])
def test_an_integer_too_large_for_a_float_is_refused_naming_the_field(kwargs, message):
    for value in (10**400, -(10**400)):
        with pytest.raises(ValueError, match=message + r".*got an integer of about 401 digits"):
            gym.make(DYN, **_with(kwargs, value))
    # the same field's finite out-of-range value is refused by the same rule
    with pytest.raises(ValueError, match=message.split(" must")[0]):
        gym.make(DYN, **_with(kwargs, 1e300))


def test_wrist_zeroing_of_a_huge_integer_is_refused_naming_the_field():
    with pytest.raises(ValueError, match="wrist zeroing must be True or False, got an integer"):
        gym.make(DYN, sensors={"wrist": {"zeroing": 10**400}})


@pytest.mark.parametrize("sensing", ["paper", "randomized"])
def test_same_seed_same_episode(sensing):
    a = _episode(gym.make(DYN, sensing=sensing), seed=5)
    b = _episode(gym.make(DYN, sensing=sensing), seed=5)
    np.testing.assert_array_equal(a[2], b[2])
    assert a[1] == b[1] and a[0]["sensing_params"] == b[0]["sensing_params"]


def test_randomized_draws_each_episode_within_the_documented_ranges():
    env = gym.make(DYN, sensing="randomized", sensors={"controller": {"inertia": 3.0}})
    seen = []
    for seed in range(4):
        _, info = env.reset(seed=seed)
        p = info["sensing_params"]
        for group, table in (("camera", CAMERA_FIELDS), ("wrist", WRIST_FIELDS),
                             ("controller", CONTROLLER_FIELDS)):
            for name, f in table.items():
                if (group, name) == ("controller", "inertia"):
                    assert p[group][name] == 3.0  # the override, over the draw
                else:
                    assert f.random[0] <= p[group][name] <= f.random[1], (group, name)
        seen.append(p["camera"]["latency"])
    assert len(set(seen)) == 4
    # reset without a seed draws the next episode's parameters, deterministically
    env.reset(seed=9)
    first = [env.reset()[1]["sensing_params"]["wrist"]["precision"] for _ in range(2)]
    env.reset(seed=9)
    again = [env.reset()[1]["sensing_params"]["wrist"]["precision"] for _ in range(2)]
    assert first == again and first[0] != first[1]


def test_the_person_is_the_same_on_every_profile():
    """The sensors draw from their own child Generator: the same seed, the same walker."""
    xy = {}
    for sensing in ("ideal", "paper", "randomized"):
        u = gym.make(DYN, sensing=sensing).unwrapped
        u.reset(seed=11, options={"receiver": "ood"})
        xy[sensing] = u.receiver.motion.camera_xy.copy()
    np.testing.assert_array_equal(xy["ideal"], xy["paper"])
    np.testing.assert_array_equal(xy["ideal"], xy["randomized"])


def test_wrist_noise_holding_the_bottle_matches_the_datasheet_precision():
    """Nobody near, the arm at rest holding the bottle: 3 sigma per axis = 3.5 N within 20 %."""
    env = gym.make(DYN)  # paper
    u = env.unwrapped
    forces = _record_ticks(env, lambda u: (u.wrist.f_ext.copy(), u.wrist.f_true.copy()))
    env.reset(seed=0, options={"receiver": "id", "walker": {"start_xy": (5.5, -1.0)}})
    for _ in range(60):  # 2 s; the walker is still > 3 m away
        env.step(READY_ACTION)
    assert np.linalg.norm(u.receiver.base()[:2] - READY_POS[:2]) > 2.0
    meas = np.array([f for f, _ in forces])
    true = np.array([t for _, t in forces])
    assert np.abs(true).max() < 0.5  # the exact force: nothing acts on the bottle
    three_sigma = 3.0 * meas[len(meas) // 4:].std(axis=0)  # after the first 0.5 s
    assert np.all(np.abs(three_sigma / 3.5 - 1.0) < 0.2), three_sigma
    assert not u.released


def test_a_release_on_the_measured_signal_before_the_grasp_is_premature():
    """A noisy sensor (20 N precision) opens the gripper before anyone holds the bottle."""
    env = gym.make(DYN, sensors={"wrist": {"precision": 20.0}})
    _, info, _ = _episode(env, seed=0)
    assert info["outcome"] == "premature_release" and info["released"]
    assert info["receiver_grasp_time"] is None
    assert info["release_force"] > 7.1 and env.unwrapped.wrist.true_magnitude() < 7.1


def test_the_command_delay_delays_the_controller_target():
    moved = {}
    for delay in (0.0, 0.05):
        env = gym.make(DYN, sensing="ideal", sensors={"controller": {"command_delay": delay}})
        u = env.unwrapped
        targets = _record_ticks(env, lambda u: u.controller.goal_pos.copy())
        env.reset(seed=0)
        env.step(np.array([0.4, -0.5, 1.2, READY_YAW], dtype=np.float32))
        env.step(np.array([0.4, -0.5, 1.2, READY_YAW], dtype=np.float32))
        goal = np.array(targets)
        moved[delay] = int(np.argmax(np.abs(goal[:, 0] - 0.4) < 1e-6))
        assert u.controller.goal_pos[0] == pytest.approx(0.4)
    assert moved[0.0] == 0 and moved[0.05] == 10  # 50 ms = 10 ticks at 200 Hz


def test_constant_m_and_lambda_controllers_are_both_available():
    ends = {}
    for m in (0.0, 4.7):
        env = gym.make(DYN, sensing="ideal", sensors={"controller": {"inertia": m}})
        u = env.unwrapped
        env.reset(seed=0)
        assert u.controller.config.mode == ("lambda" if m == 0 else "constant_m")
        for _ in range(45):
            env.step(np.array([0.4, -0.5, 1.25, READY_YAW], dtype=np.float32))
        ends[m] = u.data.site_xpos[u.ids.tcp_site].copy()
        assert np.linalg.norm(ends[m] - [0.4, -0.5, 1.25]) < 0.01  # both reach the target
    assert not np.array_equal(ends[0.0], ends[4.7])


def test_pickle_and_kwargs_keep_the_sensing_settings():
    sensors = {"camera": {"latency": 0.05}, "wrist": {"precision": 2.0}}
    env = gym.make(DYN, sensing="ideal", sensors=sensors)
    json.dumps(env.spec.kwargs)
    u2 = pickle.loads(pickle.dumps(env.unwrapped))
    assert u2.sensing == "ideal" and u2.sensor_profile.camera.latency == 0.05
    assert u2.sensor_profile.wrist.precision == 2.0


def test_static_env_runs_on_the_paper_profile():
    from agents.static import StaticAgent

    _, info, _ = _episode(gym.make(STAT), seed=0, agent=StaticAgent(), steps=600)
    assert info["sensing"] == "paper"
    assert info["outcome"] in ("success", "premature_release", "running", "dropped")


def test_sensing_sweep_quick_writes_the_paired_tables(tmp_path):
    """``evaluate.py sensing-sweep --quick``: the points, the shared paper run, the pairing."""
    import csv

    import evaluate
    from handover_eval.closedloop.sensing_sweep import FACTORS, points

    pts = points(tuple(FACTORS))
    assert sum(1 for _, _, ov in pts if not ov) == 3  # the paper point of each factor, one run
    assert ("camera_latency", 300.0, {"camera": {"latency": 0.3}}) in pts
    assert ("ft_noise", 2.0, {"wrist": {"precision": 7.0}}) in pts
    assert ("controller", 0.0, {"controller": {"inertia": 0.0}}) in pts
    out = tmp_path / "ss"
    argv = ["sensing-sweep", "--quick", "--no-progress", "--workers", "1", "--agents", "reactive",
            "ours", "--factors", "controller", "ft_noise", "--walkers", "1", "--out", str(out),
            "--checkpoints", str(tmp_path / "ck")]
    assert evaluate.main(argv) == 0
    for name in ("sensing_sweep.md", "sensing_sweep.csv", "sensing_sweep.png",
                 "sensing_sweep_paired.csv", "sensing_sweep_episodes.csv"):
        assert (out / name).stat().st_size > 0
    rows = list(csv.DictReader(open(out / "sensing_sweep.csv")))
    # 2 controller points + 4 noise points, 2 agents, 1 ID + 1 OOD walker + 3 replays (--quick)
    assert len(rows) == 12 and all(r["n"] == "5" for r in rows)
    eps = list(csv.DictReader(open(out / "sensing_sweep_episodes.csv")))
    paper = [e for e in eps if (e["factor"], e["value"]) == ("controller", "4.7")]
    same = [e for e in eps if (e["factor"], e["value"]) == ("ft_noise", "1")]
    assert [e["outcome"] for e in paper] == [e["outcome"] for e in same]  # one shared run
    pairs = list(csv.DictReader(open(out / "sensing_sweep_paired.csv")))
    assert {p["agent"] for p in pairs} == {"ours"}
    assert {p["metric"] for p in pairs} == {"success", "handover_time", "premature_release"}
    text = (out / "sensing_sweep.md").read_text()
    assert "Δ success pp vs reactive" in text and "4.7 (paper)" in text
    assert evaluate.main(argv[:-4] + ["--factors", "wind", "--out", str(out)]) == 2
