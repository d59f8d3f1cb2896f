"""Issues 16 (items 16-19) and 20 (items 3-5, 10): the env refuses bad input before touching its
state, says which input and what range, and leaves nothing behind in the repository."""

from __future__ import annotations

import copy
import dataclasses
import pickle
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import handover_env  # noqa: F401
from handover_env.data.dataset import Episode
from handover_env.data.errors import DatasetError
from handover_env.data.limits import MIN_BONE_M
from handover_env.person import motion as rm
from handover_env.person import trajectory
from handover_env.person.gait import walking_pose
from handover_env.person.person import replay_input
from handover_env.person.recording import Recording, load_recording
from handover_env.person.settings import (
    LONGEST_EPISODE,
    SETTING_RANGES,
    ReceiverConfig,
    person_config,
)
from handover_env.person.skeleton import BodyDims, joints_of, shortest_bone

ENV_ID = "handover_env/DynamicHandover-v0"
REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"


def test_step_before_reset_and_after_a_failed_reset_raise_clearly():
    env = gym.make(ENV_ID).unwrapped
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    env.reset(seed=0)
    env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    clock = env.data.time
    with pytest.raises(ValueError, match="height"):
        env.reset(seed=0, options={"height": 9.0})
    assert env.data.time == clock  # the failed reset touched nothing ...
    with pytest.raises(RuntimeError, match="reset"):
        env.step(
            np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32)
        )  # ... but the env must be reset


def test_a_copy_of_a_running_env_is_a_fresh_env_that_says_so():
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    for twin in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        with pytest.raises(RuntimeError, match="fresh"):
            twin.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
        obs, _ = twin.reset(seed=0)
        assert twin.observation_space.contains(obs)


@pytest.mark.parametrize(
    "action",
    [
        np.zeros((2, 2), dtype=np.float32),
        np.zeros((1, 4), dtype=np.float32),
        np.zeros((4, 1), dtype=np.float32),
        np.array(["0.3", "-0.4", "1.1", "0"]),
        np.array([0.3, -0.4, 1.1, 1j]),
        np.array([0.3, np.inf, 1.1, 0.0]),
    ],
)
def test_malformed_actions_are_refused(action):
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(action)


def test_constructor_checks():
    gym.make(
        ENV_ID, stiffness=np.float32(100.0), damping=np.float64(15.0)
    )  # numpy numbers are numbers
    with pytest.raises(ValueError, match="history"):
        gym.make(ENV_ID, history=2.5)
    for kw in ({"width": 0}, {"height": -1}, {"width": 12.5}):
        with pytest.raises(ValueError, match="pixels"):
            gym.make(ENV_ID, render_mode="rgb_array", **kw)


def test_human_rendering_without_a_display_is_a_python_error(monkeypatch, tmp_path):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(RuntimeError, match="display"):
        gym.make(ENV_ID, render_mode="human")
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_unknown_reset_options_warn_by_name():
    env = gym.make(ENV_ID)
    with pytest.warns(UserWarning, match="reciever"):
        env.reset(seed=0, options={"reciever": "ood"})


def test_a_diverging_simulation_ends_the_episode_as_unstable(monkeypatch, tmp_path):
    # MuJoCo's warning handler appends to MUJOCO_LOG.TXT in the working directory: run the
    # divergence in tmp_path so that `make test` leaves nothing in the repository.
    log = REPO / "MUJOCO_LOG.TXT"
    before = (log.stat().st_size, log.stat().st_mtime_ns) if log.exists() else None
    monkeypatch.chdir(tmp_path)
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    env.data.qvel[env.ids.object_dof:env.ids.object_dof + 3] = 1e30  # blow it up
    *_, terminated, _, info = env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    assert terminated and info["outcome"] == "unstable" and not info["is_success"]
    assert (tmp_path / "MUJOCO_LOG.TXT").exists()  # MuJoCo did warn, here
    after = (log.stat().st_size, log.stat().st_mtime_ns) if log.exists() else None
    assert after == before  # ... and wrote nothing into the repository root


# ---------------------------------------------------------------- issue 20: the env's inputs
ACTION = np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32)


@pytest.fixture(scope="module")
def dyn():
    return gym.make(ENV_ID).unwrapped


def _refused_cleanly(env, match: str, exc: type[Exception] = ValueError, **reset_kw) -> None:
    """``reset(**reset_kw)`` raises one clear error and loses nothing: the simulation is
    untouched, the env must be reset again, and a valid reset then works."""
    env.reset(seed=0)
    env.step(ACTION)
    clock, qpos = env.data.time, env.data.qpos.copy()
    with pytest.raises(exc, match=match):
        env.reset(seed=0, **reset_kw)
    assert env.data.time == clock and np.array_equal(env.data.qpos, qpos)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(ACTION)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


# Item 3: walker options.
def test_every_numeric_walker_field_has_a_range_that_holds_what_the_sampler_draws():
    numeric = {f.name for f in dataclasses.fields(rm.WalkerParams)} - {
        "kind", "ood_mode", "start_xy"
    }
    assert set(rm.FIELD_RANGES) == numeric
    rng = np.random.default_rng(0)
    for kind in ("id", "ood", "id", "ood"):
        for _ in range(100):
            w = rm.sample_walker(rng, kind)
            for name, (lo, hi, *_) in rm.FIELD_RANGES.items():
                assert lo <= getattr(w, name) <= hi, name
            assert max(abs(v) for v in w.start_xy) <= rm.WALK_HALF_SIZE


def test_the_walk_area_is_the_scenes_floor(dyn):
    floor = mujoco.mj_name2id(dyn.model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    assert tuple(dyn.model.geom_size[floor][:2]) == (rm.FLOOR_HALF_SIZE, rm.FLOOR_HALF_SIZE)
    assert rm.PELVIS_LIMIT + rm.BODY_HALF_WIDTH == rm.FLOOR_HALF_SIZE
    # The body's sideways reach while walking is within BODY_HALF_WIDTH for the tallest body.
    assert rm.HAND_REST_LATERAL_RATIO * rm.HEIGHT_RANGE[1] <= rm.BODY_HALF_WIDTH


@pytest.mark.parametrize("field", ["pass_y", "end_x", "start_bulge", "sway_amplitude"])
@pytest.mark.parametrize("value", [1e9, -1e9])
def test_walker_fields_of_the_issue_are_refused_by_name_and_range(dyn, field, value):
    lo, hi, *_ = rm.FIELD_RANGES[field]
    _refused_cleanly(dyn, rf"walker {field} must be in \[{lo:g}, {hi:g}\]",
                     options={"walker": {field: value}})


@pytest.mark.parametrize("field", sorted(rm.FIELD_RANGES))
def test_every_walker_field_is_checked(dyn, field):
    lo, hi, *_ = rm.FIELD_RANGES[field]
    for bad in (hi + 1.0, lo - 1.0, 1e300, float("nan"), float("inf")):
        with pytest.raises(
            ValueError, match=rf"walker {field} must be (finite and )?in \[{lo:g}, {hi:g}\]"
        ):
            dyn.reset(seed=0, options={"walker": {field: bad}})
    for not_a_number in (True, np.bool_(False), "0.5", None, [0.5]):
        with pytest.raises(ValueError, match=rf"walker {field} must be a number"):
            dyn.reset(seed=0, options={"walker": {field: not_a_number}})
    # Fixing a field to the value the seed draws anyway changes nothing.
    free, _ = dyn.reset(seed=3, options={"receiver": "ood"})
    drawn = dyn.receiver.walker
    fixed, _ = dyn.reset(
        seed=3, options={"receiver": "ood", "walker": {field: getattr(drawn, field)}}
    )
    assert dyn.receiver.walker == drawn and np.array_equal(fixed, free)


@pytest.mark.parametrize(
    "walker, match",
    [
        ({"kind": "ood"}, "'kind' is not an override.*receiver option"),
        ({"kind": "id"}, "'kind' is not an override"),
        ({"ood_mode": "crawl"}, "ood_mode"),
        ({"start_xy": (1e9, -0.5)}, r"start_xy must lie in \[-5.5, 5.5\]"),
        ({"start_xy": ("2.0", "-0.5")}, "start_xy must be a pair of numbers"),
        ({"start_xy": (True, -0.5)}, "start_xy must be a pair of numbers"),
        ({"start_xy": (2.0, -0.5, 0.0)}, "start_xy must be a pair of numbers"),
        ({"start_xy": "ab"}, "start_xy must be a pair of numbers"),
        ({"velocity": 1.0}, "unknown WalkerParams field"),
        ({1: 1.0}, "names must be strings"),
        ([1, 2], "dict of WalkerParams fields"),
    ],
)
def test_walker_options_that_are_not_walker_fields(dyn, walker, match):
    _refused_cleanly(dyn, match, options={"walker": walker})


def test_walkers_that_would_leave_the_floor_or_never_arrive_are_refused(dyn):
    # Each field is in range, together they swing the path off the floor ...
    _refused_cleanly(dyn, "leaves the floor", options={"walker": {
        "start_xy": (5.4, -5.4), "start_turn": -1.5, "start_bulge": 3.0, "pass_y": -5.0}})
    # ... or take minutes to walk 11 m.
    _refused_cleanly(dyn, "MAX_WALK_TIME", options={"speed": 0.1, "walker": {
        "start_xy": (5.4, -1.0), "end_x": -5.4, "speed_ripple": 0.45, "drift_amplitude": 0.4}})


def test_the_static_env_checks_the_walker_before_its_stop_line_replaces_it():
    env = gym.make("handover_env/StaticHandover-v0").unwrapped
    _refused_cleanly(env, r"walker pass_y must be in", options={"walker": {"pass_y": 1e9}})
    _refused_cleanly(env, "dict of WalkerParams fields", options={"walker": [1, 2]})


@pytest.mark.parametrize(
    "options, match",
    [
        ({"height": True}, "height must be a number"),
        ({"height": "1.8"}, "height must be a number"),
        ({"height": float("nan")}, r"height must be finite and in \[1.2, 2.2\] m"),
        ({"speed": 1e300}, r"speed must be in \[0.1, 2.5\] m/s"),
        ({"speed": np.bool_(True)}, "speed must be a number"),
    ],
)
def test_height_and_speed_options_are_real_numbers_in_range(dyn, options, match):
    _refused_cleanly(dyn, match, options=options)


def test_reset_options_must_be_a_dict(dyn):
    _refused_cleanly(dyn, "options must be a dict", options=[("receiver", "ood")])


# Item 4: replays given as a dict, a Recording or an Episode: one validation.
def _skeleton_walk(frames: int = 120):
    """A receiver walking toward -x with a full BODY_34 skeleton (the scripted gait)."""
    t = np.arange(frames) / 30.0
    xy = np.stack([2.2 - 0.9 * t, np.full_like(t, -0.9)], axis=1)
    phase = np.mod(2 * np.pi * 0.9 * t / (2 * 0.28 * 1.725), 2 * np.pi)
    traj = trajectory.BaseTrajectory(t=t, xy=xy, heading=np.full(frames, np.pi), gait_phase=phase)
    dims = BodyDims.from_height(1.725)
    return xy, joints_of(walking_pose(traj, dims), dims)


def _episode(xy: np.ndarray, joints: np.ndarray) -> Episode:
    n = len(xy)
    return Episode(receiver_xy=xy, receiver_hand_xyz=joints[:, 15], giver_xyz=np.tile(
        [0.3, -0.5, 1.2], (n, 1)), object_quat=np.tile([1.0, 0, 0, 0], (n, 1)), is_ood=False,
        source_id="crafted")


def _replay(episode) -> dict:
    return {"options": {"receiver": "replay", "episode": episode}}


def test_valid_replays_in_every_form_are_accepted(dyn):
    xy, joints = _skeleton_walk()
    for episode in ({"receiver_xy": xy}, {"receiver_xy": xy.tolist(), "receiver_pose": joints},
                    _episode(xy, joints), Recording(_episode(xy, joints), joints.copy()),
                    {"receiver_xy": np.round(xy * 1000).astype(np.int64) / 1000}):
        obs, info = dyn.reset(seed=0, **_replay(episode))
        assert dyn.observation_space.contains(obs) and info["receiver_id"]


@pytest.mark.parametrize(
    "craft, match",
    [
        (lambda xy, j: {"receiver_xy": xy * 1e300}, r"receiver_xy reaches .* the \+-100 m"),
        (lambda xy, j: {"receiver_xy": xy + 1e6}, r"receiver_xy reaches 1e\+06 m"),  # 1,000 km
        (lambda xy, j: {"receiver_xy": xy.astype(str)}, "receiver_xy must be an array of real"),
        (lambda xy, j: {"receiver_xy": xy.astype(object)}, "receiver_xy must be an array of real"),
        (lambda xy, j: {"receiver_xy": xy > 0}, "receiver_xy must be an array of real"),
        (lambda xy, j: {"receiver_xy": xy + 0j}, "receiver_xy must be an array of real"),
        (lambda xy, j: {"receiver_xy": [[0.0, 1.0], [0.0]]}, "receiver_xy is not an array"),
        (lambda xy, j: {"receiver_xy": xy[:1]}, r"receiver_xy must have shape \(T>=2, 2\)"),
        (lambda xy, j: {"receiver_xy": xy, "receiver_pose": j * 1e300},
         r"receiver_pose reaches .* the \+-100 m"),
        (lambda xy, j: {"receiver_xy": xy, "receiver_pose": np.zeros_like(j)},
         "receiver_pose is degenerate: bone .* 0.0 mm long at frame 0"),
        (lambda xy, j: {"receiver_xy": xy, "receiver_pose": j.astype(str)},
         "receiver_pose must be an array of real"),
        (lambda xy, j: {"receiver_xy": xy, "receiver_pose": j.astype(object)},
         "receiver_pose must be an array of real"),
        (lambda xy, j: {"receiver_xy": xy, "receiver_pose": j[:-1]},
         r"receiver_pose must have shape \(120, 34, 3\)"),
        (lambda xy, j: {"receiver_xy": xy, "receiver_pose": j - [0, 0, 3.0]}, "body height"),
        (lambda xy, j: {"receiver_xy": xy, "source_id": 7}, "source_id must be a string"),
        (lambda xy, j: [xy], "a Recording, an Episode or a dict"),
    ],
)
def test_crafted_replay_dicts_are_refused(dyn, craft, match):
    xy, joints = _skeleton_walk()
    _refused_cleanly(dyn, match, **_replay(craft(xy, joints)))


def test_one_collapsed_frame_is_enough_to_refuse_a_skeleton(dyn):
    xy, joints = _skeleton_walk()
    joints[37, 12:16] = joints[37, 12]  # the right arm collapsed onto the shoulder
    _refused_cleanly(dyn, "degenerate: bone RIGHT_ELBOW-RIGHT_SHOULDER .* at frame 37",
                     **_replay({"receiver_xy": xy, "receiver_pose": joints}))


@pytest.mark.parametrize(
    "bad, match",
    [
        (lambda j: np.zeros_like(j), "receiver_pose is degenerate"),
        (lambda j: j * 1e300, r"receiver_pose reaches .* \+-100 m"),
        (lambda j: j + 1e6, r"receiver_pose reaches 1e\+06 m"),
        (lambda j: j.astype(str), "receiver_pose must be an array of real"),
        (lambda j: j.astype(object), "receiver_pose must be an array of real"),
    ],
)
def test_crafted_recordings_are_refused_when_made_and_when_replayed(dyn, bad, match):
    xy, joints = _skeleton_walk()
    with pytest.raises(DatasetError, match="crafted: " + match):
        Recording(_episode(xy, joints), bad(joints))
    # A Recording whose skeleton was swapped after its checks is checked again at replay.
    rec = Recording(_episode(xy, joints), joints)
    object.__setattr__(rec, "receiver_pose", bad(joints))
    _refused_cleanly(dyn, "replay " + match, **_replay(rec))


def test_a_crafted_public_file_with_an_all_zero_skeleton_is_refused(tmp_path):
    from crafted import good_record

    record = good_record()
    record["pose_receiver"] = np.zeros_like(record["pose_receiver"])
    path = tmp_path / "motion_normal_0.pkl"
    path.write_bytes(pickle.dumps(record, protocol=4))
    with pytest.raises(DatasetError, match="motion_normal_0: receiver_pose is degenerate"):
        load_recording(path)


def test_replayed_recordings_of_the_development_copy_pass_the_replay_checks():
    if not DATA.is_dir():
        pytest.skip("the development copy of the dataset is not at ../shared/data")
    for path in sorted(DATA.glob("*.pkl"))[::40]:
        rec = load_recording(path)
        xy, pose, source_id = replay_input(rec)
        assert pose is not None and source_id == path.stem
        assert shortest_bone(pose)[0] > 4 * MIN_BONE_M


# Item 5: person overrides.
@pytest.mark.parametrize("field", ["reach_duration", "close_time"])
def test_person_durations_of_the_issue_are_refused_by_name(field):
    lo, hi, *_ = SETTING_RANGES[field]
    with pytest.raises(ValueError, match=rf"person setting {field} must be in \[{lo:g}, "):
        gym.make(ENV_ID, person={field: 1e300})


@pytest.mark.parametrize("field", sorted(SETTING_RANGES))
def test_every_person_setting_is_checked(field):
    lo, hi, *_ = SETTING_RANGES[field]
    assert lo <= getattr(ReceiverConfig(), field) <= hi  # the calibrated default is in range
    for bad in (hi + 1.0, lo - 1.0, 1e300, float("nan"), -float("inf")):
        with pytest.raises(ValueError, match=rf"person setting {field} must be (finite and )?in"):
            person_config({field: bad}, miss_distance=0.35)
    for not_a_number in (True, np.bool_(True), "0.5", None, [0.5]):
        with pytest.raises(ValueError, match=rf"person setting {field} must be a number"):
            person_config({field: not_a_number}, miss_distance=0.35)
    assert getattr(person_config({field: lo}, miss_distance=0.35), field) == lo  # closed range
    assert getattr(person_config({field: hi}, miss_distance=0.35), field) == hi
    value = np.float32(getattr(ReceiverConfig(), field))  # numpy numbers are numbers ...
    config = person_config({field: value}, miss_distance=0.35)
    assert getattr(config, field) == float(value) and type(getattr(config, field)) is float


def test_the_time_ranges_come_from_the_registered_episodes():
    longest = max(
        gym.spec(env_id).max_episode_steps
        for env_id in ("handover_env/DynamicHandover-v0", "handover_env/StaticHandover-v0")
    ) / 30.0
    assert LONGEST_EPISODE == longest and rm.MAX_WALK_TIME == 6 * longest
    assert SETTING_RANGES["reach_duration"][1] == longest


@pytest.mark.parametrize(
    "person, match",
    [
        ([1, 2], "person must be a dict of ReceiverConfig settings, got list"),
        ("reach_duration=1", "person must be a dict"),
        ({"reach_time": 1.0}, "unknown person setting"),
        ({3: 1.0}, "unknown person setting"),
        ({"reach_duration": True}, "reach_duration must be a number"),
    ],
)
def test_person_must_be_a_dict_of_known_settings(person, match):
    with pytest.raises(ValueError, match=match):
        gym.make(ENV_ID, person=person)


def test_miss_distance_is_checked_as_the_persons_give_up_distance():
    with pytest.raises(ValueError, match="miss_distance .* give_up_behind"):
        gym.make(ENV_ID, miss_distance=1e300)


def test_person_settings_in_range_make_a_working_env():
    env = gym.make(ENV_ID, person={"reach_duration": 1, "close_time": np.float64(0.3)}).unwrapped
    assert env.receiver.config.reach_duration == 1.0 and env.receiver.config.close_time == 0.3
    assert env.receiver.config.give_up_behind == env.miss_distance
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(env.step(ACTION)[0]) and env.observation_space.contains(
        obs)


@pytest.mark.parametrize(
    "value", [10**400, -(10**400), 10**5000], ids=["1e400", "-1e400", "1e5000"]
)
def test_a_number_too_large_for_a_float_is_named(value):
    """An integer beyond float range is one ValueError naming the setting, not an OverflowError."""
    from handover_env.numbers import checked_number

    with pytest.raises(
        ValueError, match=(
            r"walker pass_y must be finite and in \[-2, 2\] m, "
            r"got an integer of about \d+ digits"
        ),
    ):
        checked_number("walker pass_y", value, -2.0, 2.0, "m")
    env = gym.make("handover_env/DynamicHandover-v0")
    with pytest.raises(ValueError, match=r"walker speed .*got an integer of about \d+ digits"):
        env.reset(seed=0, options={"walker": {"speed": value}})
    env.close()


@pytest.mark.parametrize(
    "name", ["motion_normal_0.pkl.bak", "motion_normal_0.pkl\n", "x_motion_normal_0.pkl"]
)
def test_a_recording_name_must_match_in_full(tmp_path, name):
    """``load_recording`` takes the public file name in full (a suffix or a newline is no match)."""
    from crafted import good_record

    path = tmp_path / name
    path.write_bytes(pickle.dumps(good_record(), protocol=4))
    with pytest.raises(DatasetError, match="not a public-dataset file name"):
        load_recording(path)
