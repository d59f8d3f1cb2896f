"""Sensor models of issue 24 (handover_env.sensors): camera, wrist F/T, profiles and overrides."""

from __future__ import annotations

import math

import numpy as np
import pytest

from handover_env.person.motion import sample_walker
from handover_env.person.trajectory import base_trajectory
from handover_env.sensors import (
    Camera,
    CameraParams,
    ControllerParams,
    WristFT,
    WristFTParams,
    make_profile,
)
from handover_env.sensors.profiles import CAMERA_FIELDS, CONTROLLER_FIELDS, WRIST_FIELDS
from handover_eval.calibration.sensing import ar1_highpass, track_jitter

DT_TICK = 0.005  # the env's 200 Hz controller tick
GRAVITY_SF = np.array([0.0, 0.0, 9.81])  # accelerometer reading of a payload at rest


def _run_camera(params: CameraParams, seed: int, n: int = 300, point=None):
    cam = Camera(params).reset(np.random.default_rng(seed))
    out = []
    for k in range(n):
        t = k / params.rate_hz
        p = np.array([0.01 * k, -0.5]) if point is None else np.asarray(point)
        out.append(cam.frame(t, {"pelvis": p, "hand": np.array([0.0, 0.0, 1.0])}))
    return out


def _walker_tracks(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [base_trajectory(sample_walker(rng, "id")) for _ in range(n)]


# ------------------------------------------------------------------------------------ camera
def test_camera_is_deterministic_under_a_seed():
    a, b = _run_camera(CameraParams(), 3), _run_camera(CameraParams(), 3)
    c = _run_camera(CameraParams(), 4)
    assert all(np.array_equal(x.points["pelvis"], y.points["pelvis"]) and x.tracked == y.tracked
               for x, y in zip(a, b))
    assert not all(np.array_equal(x.points["pelvis"], y.points["pelvis"]) for x, y in zip(a, c))


def test_ideal_camera_sees_the_truth_now():
    cam = Camera(make_profile("ideal").camera).reset(np.random.default_rng(0))
    for k in range(50):
        p = np.array([0.03 * k, -0.9])
        obs = cam.frame(k / 30.0, {"pelvis": p})
        assert obs.tracked and obs.t_capture == k / 30.0
        np.testing.assert_array_equal(obs.points["pelvis"], p)


def test_latency_delays_by_whole_frames_and_flags_the_start():
    params = CameraParams(latency=0.1, pelvis_sigma=0.0, hand_sigma=0.0, lost_fraction=0.0)
    assert Camera(params).delay_frames == 3  # 100 ms at 30 Hz
    obs = _run_camera(params, 0, n=20)
    assert [o.tracked for o in obs[:3]] == [False] * 3 and all(o.tracked for o in obs[3:])
    for k in range(3, 20):
        np.testing.assert_allclose(obs[k].points["pelvis"], [0.01 * (k - 3), -0.5])
        assert obs[k].t_capture == pytest.approx((k - 3) / 30.0)
    assert Camera(CameraParams(latency=0.101)).delay_frames == 4


def test_lost_frames_have_the_stated_fraction_and_run_and_hold_the_last_frame():
    params = CameraParams(latency=0.0, pelvis_sigma=0.0, hand_sigma=0.0,
                          lost_fraction=0.2, lost_run=3.0)
    obs = _run_camera(params, 1, n=30000)
    lost = np.array([not o.tracked for o in obs])
    assert lost.mean() == pytest.approx(0.2, abs=0.02)
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, lost.astype(int), 0])))[::2]
    assert runs.mean() == pytest.approx(3.0, rel=0.1)
    for k in np.flatnonzero(lost)[:200]:
        if k == 0 or not obs[k - 1].tracked:
            continue
        np.testing.assert_array_equal(obs[k].points["pelvis"], obs[k - 1].points["pelvis"])
        assert obs[k].t_capture == obs[k - 1].t_capture


def test_keypoint_noise_has_its_sigma_and_correlation():
    params = CameraParams(latency=0.0, lost_fraction=0.0, pelvis_sigma=0.01, pelvis_rho=0.0,
                          hand_sigma=0.05, hand_rho=0.9)
    obs = _run_camera(params, 2, n=40000, point=[0.0, 0.0])
    hand = np.array([o.points["hand"] for o in obs]) - [0.0, 0.0, 1.0]
    pel = np.array([o.points["pelvis"] for o in obs])
    assert hand.std() == pytest.approx(0.05, rel=0.05)
    assert np.sum(hand[1:] * hand[:-1]) / np.sum(hand * hand) == pytest.approx(0.9, abs=0.02)
    assert pel.std() == pytest.approx(0.01, rel=0.03)
    assert abs(np.sum(pel[1:] * pel[:-1]) / np.sum(pel * pel)) < 0.03


def test_paper_camera_jitter_is_its_white_noise_through_the_statistic():
    """On smooth scripted walks the paper camera's jitter is set by pelvis_sigma (sensing.py)."""
    params = make_profile("paper").camera
    walks = _walker_tracks(30)
    seen = []
    for i, tr in enumerate(walks):
        cam = Camera(params).reset(np.random.default_rng(100 + i))
        seen.append(np.array([cam.frame(float(t), {"pelvis": xy}).points["pelvis"]
                              for t, xy in zip(tr.t, tr.xy)]))
    walker = track_jitter([tr.xy for tr in walks])
    expected = math.hypot(walker, params.pelvis_sigma * math.sqrt(ar1_highpass(0.0)[0]))
    assert track_jitter(seen) == pytest.approx(expected, rel=0.05)
    assert walker < 0.3 * track_jitter(seen)  # the statistic measures the camera, not the walk


def test_camera_refuses_bad_calls():
    cam = Camera()
    with pytest.raises(RuntimeError, match="reset"):
        cam.frame(0.0, {"pelvis": [0.0, 0.0]})
    cam.reset(np.random.default_rng(0))
    with pytest.raises(ValueError, match="unknown keypoint 'head'"):
        cam.frame(0.0, {"head": [0.0, 0.0, 1.0]})
    with pytest.raises(ValueError, match="pelvis"):
        cam.frame(0.0, {"pelvis": [0.0, math.nan]})
    cam.frame(1.0, {"pelvis": [0.0, 0.0]})
    with pytest.raises(ValueError, match="go back"):
        cam.frame(0.5, {"pelvis": [0.0, 0.0]})
    with pytest.raises(ValueError, match="Generator"):
        Camera().reset(0)


# ------------------------------------------------------------------------------------ wrist F/T
def _hold_still(params: WristFTParams, seed: int, seconds: float, zero_at: float = 1.0):
    ft = WristFT(params).reset(np.random.default_rng(seed), 1.325, (0.0, 0.0, 0.12))
    out = []
    for k in range(int(seconds / DT_TICK)):
        out.append(ft.measure(np.zeros(3), GRAVITY_SF, np.eye(3), DT_TICK))
        if k == int(zero_at / DT_TICK):
            ft.zero()
    return ft, np.array(out)


def test_wrist_noise_matches_the_datasheet_precision_holding_the_bottle():
    """Robot at rest holding the bottle, nobody near: 3 sigma per axis = 3.5 N (+-20 %)."""
    params = make_profile("paper").wrist
    _, f = _hold_still(params, 5, 21.0)
    windows = f[int(1.0 / DT_TICK):].reshape(-1, int(2.0 / DT_TICK), 3)  # 2 s, drift included
    three_sigma = 3.0 * windows.std(axis=1).mean(axis=0)
    assert three_sigma == pytest.approx([params.precision] * 3, rel=0.2)


def test_zeroing_removes_the_static_payload_error_and_a_rotation_brings_it_back():
    params = WristFTParams(precision=0.0, drift=0.0, mass_error=0.2, com_error=0.0, accuracy=4.0)
    ft, f = _hold_still(params, 6, 2.0)
    assert np.linalg.norm(f[int(0.5 / DT_TICK)]) > 0.5  # offset and Δm g before zeroing
    np.testing.assert_allclose(f[-1], 0.0, atol=1e-9)
    # Turn the wrist 90 deg about x: the tared Δm g and offset no longer cancel.
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    for _ in range(200):
        g = ft.measure(np.zeros(3), GRAVITY_SF, rot, DT_TICK)
    assert np.linalg.norm(g) > 0.5


def test_a_moving_payload_with_a_wrong_mass_reads_a_spurious_force():
    params = WristFTParams(precision=0.0, accuracy=0.0, drift=0.0, mass_error=0.1, com_error=0.0,
                           filter_tau=0.0)
    ft = WristFT(params).reset(np.random.default_rng(7), 1.3, (0.0, 0.0, 0.1))
    dm = ft.mass_error
    ft.measure(np.zeros(3), GRAVITY_SF, np.eye(3), DT_TICK)
    ft.zero()
    f = ft.measure(np.zeros(3), GRAVITY_SF + [3.0, 0.0, 0.0], np.eye(3), DT_TICK)
    np.testing.assert_allclose(f, [dm * 3.0, 0.0, 0.0], atol=1e-12)
    assert ft.configured_payload[0] == pytest.approx(1.3 + dm)


def test_ideal_wrist_is_the_envs_filtered_force_and_draws_nothing():
    rng = np.random.default_rng(8)
    state = rng.bit_generator.state
    ft = WristFT(make_profile("ideal").wrist).reset(rng, 1.3, (0.0, 0.0, 0.1))
    a = DT_TICK / (0.015 + DT_TICK)  # the env's force_filter_tau = 15 ms at 200 Hz
    forces = np.random.default_rng(9).normal(0.0, 5.0, (100, 3))
    y = None
    for x in forces:
        got = ft.measure(x, GRAVITY_SF, np.eye(3), DT_TICK)
        y = x if y is None else y + a * (x - y)
        np.testing.assert_allclose(got, y, atol=1e-12)
    ft.zero()  # zeroing is off in the ideal world
    np.testing.assert_allclose(ft.measure(forces[-1], GRAVITY_SF, np.eye(3), DT_TICK),
                               y + a * (forces[-1] - y), atol=1e-12)
    assert rng.bit_generator.state == state


def test_wrist_is_deterministic_and_refuses_bad_input():
    a = _hold_still(WristFTParams(), 11, 1.5)[1]
    b = _hold_still(WristFTParams(), 11, 1.5)[1]
    np.testing.assert_array_equal(a, b)
    ft = WristFT()
    with pytest.raises(RuntimeError, match="reset"):
        ft.measure(np.zeros(3), GRAVITY_SF, np.eye(3), DT_TICK)
    ft.reset(np.random.default_rng(0), 1.0, (0, 0, 0))
    with pytest.raises(ValueError, match="true_force_world"):
        ft.measure([0.0, math.inf, 0.0], GRAVITY_SF, np.eye(3), DT_TICK)
    with pytest.raises(ValueError, match="dt"):
        ft.measure(np.zeros(3), GRAVITY_SF, np.eye(3), 0.0)
    with pytest.raises(ValueError, match="rotation"):
        ft.measure(np.zeros(3), GRAVITY_SF, np.eye(2), DT_TICK)
    with pytest.raises(ValueError, match="payload_mass"):
        ft.set_payload(-1.0, (0, 0, 0))


# ------------------------------------------------------------------------------------ profiles
def test_paper_and_ideal_profiles():
    paper, ideal = make_profile("paper"), make_profile("ideal")
    assert paper.camera.rate_hz == 30.0 and paper.controller.control_rate_hz == 200.0
    assert paper.wrist.precision == 3.5 and paper.wrist.accuracy == 4.0
    assert paper.controller.joint_speed_limit == pytest.approx(math.pi)
    assert ideal.camera.latency == 0 and ideal.camera.pelvis_sigma == 0
    assert ideal.camera.lost_fraction == 0 and ideal.wrist.mass_error == 0
    assert not ideal.wrist.zeroing and ideal.controller.inertia == 0
    assert ideal.controller.command_delay == 0


def test_randomized_profile_is_seeded_and_within_its_ranges():
    a = make_profile("randomized", rng=np.random.default_rng(1))
    b = make_profile("randomized", rng=np.random.default_rng(1))
    c = make_profile("randomized", rng=np.random.default_rng(2))
    assert a == b and a != c
    for group, table in (("camera", CAMERA_FIELDS), ("wrist", WRIST_FIELDS),
                         ("controller", CONTROLLER_FIELDS)):
        for name, f in table.items():
            v = getattr(getattr(a, group), name)
            assert f.random[0] <= v <= f.random[1] and f.lo <= v <= f.hi, (group, name)
    with pytest.raises(ValueError, match="Generator"):
        make_profile("randomized")


def test_overrides_apply_and_bad_ones_name_the_field():
    p = make_profile("paper", {"camera": {"latency": 0.2}, "wrist": {"zeroing": False}})
    assert p.camera.latency == 0.2 and not p.wrist.zeroing and p.wrist.precision == 3.5
    r = make_profile("randomized", {"controller": {"inertia": 3.0}}, rng=np.random.default_rng(0))
    assert r.controller.inertia == 3.0
    bad = [
        ([("camera", "latency")], "must be a dict"),
        ({"lidar": {}}, "unknown sensor override group"),
        ({"camera": 0.1}, "camera overrides must be a dict"),
        ({"camera": {"latncy": 0.1}}, r"unknown camera field\(s\) \['latncy'\]"),
        ({"camera": {"latency": True}}, "camera latency must be a number"),
        ({"camera": {"latency": "0.1"}}, "camera latency must be a number"),
        ({"wrist": {"precision": math.nan}}, "wrist precision must be finite"),
        ({"wrist": {"precision": -1.0}}, r"wrist precision must be in \[0, 20\] N"),
        ({"controller": {"command_delay": 1.0}}, "controller command_delay must be in"),
        ({"wrist": {"zeroing": 1}}, "wrist zeroing must be True or False"),
    ]
    for overrides, message in bad:
        with pytest.raises(ValueError, match=message):
            make_profile("paper", overrides)
    with pytest.raises(ValueError, match="unknown sensor profile"):
        make_profile("real")
    with pytest.raises(ValueError, match="camera lost_run"):
        CameraParams(lost_run=0.5)
    with pytest.raises(ValueError, match="controller inertia"):
        ControllerParams(inertia=-2.0)
