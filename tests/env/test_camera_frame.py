"""The camera's compiled frame (handover_env.sensors.camera_frame): its random numbers are the
Generator's stream in order, blocks drawn when first needed; the env's unchecked call and the
checked ``Camera.frame`` are the same frame."""

from __future__ import annotations

import numpy as np
import pytest

from handover_env.sensors import Camera, CameraParams, make_profile
from handover_env.sensors import camera_frame as cf

QUIET = {"latency": 0.0, "pelvis_sigma": 0.0, "hand_sigma": 0.0, "lost_fraction": 0.0}


def test_noise_is_the_generators_normals_in_order_across_blocks():
    """A 3-D hand at the origin with white noise (rho 0): frame k shows sigma z_3k..z_3k+2, the
    stream of standard normals drawn 256 at a time (a frame straddles each block's end)."""
    params = CameraParams(**{**QUIET, "hand_sigma": 0.05, "hand_rho": 0.0})
    cam = Camera(params).reset(np.random.default_rng(7))
    seen = np.array([cam.frame(k / 30.0, {"hand": np.zeros(3)}).points["hand"]
                     for k in range(400)])
    z = np.random.default_rng(7).standard_normal(5 * cf.BLOCK)[:1200]
    np.testing.assert_array_equal(seen.ravel(), 0.05 * z)


def test_lost_frames_are_the_chain_on_the_generators_uniforms():
    params = CameraParams(**{**QUIET, "lost_fraction": 0.3, "lost_run": 4.0})
    cam = Camera(params).reset(np.random.default_rng(3))
    tracked = [cam.frame(k / 30.0, {"pelvis": np.zeros(2)}).tracked for k in range(600)]
    u = np.random.default_rng(3).random(3 * cf.BLOCK)
    stay, start = 1.0 - 1.0 / 4.0, 0.3 / (4.0 * 0.7)
    lost, expected = False, []
    for k in range(600):
        lost = bool(u[k] < (stay if lost else start))
        expected.append(not lost)
    assert tracked == expected and 100 < tracked.count(False) < 300


@pytest.mark.parametrize("profile", ["paper", "randomized"])
def test_normals_and_uniforms_are_drawn_in_blocks_when_first_needed(profile):
    """Five normals and one uniform a frame: the Generator ends where drawing the blocks in that
    schedule (normals before uniforms within a frame) leaves it."""
    params = make_profile(profile, rng=np.random.default_rng(1)).camera
    cam = Camera(params).reset(np.random.default_rng(11))
    for k in range(700):
        cam.capture(k / 30.0, np.array([0.1, 0.2, 1.0]), np.array([0.5 * k / 700, -1.0]))
    ref = np.random.default_rng(11)
    normals = uniforms = used_n = used_u = 0
    for _ in range(700):
        if used_n + 5 > normals:
            ref.standard_normal(cf.BLOCK)
            normals += cf.BLOCK
        if used_u + 1 > uniforms:
            ref.random(cf.BLOCK)
            uniforms += cf.BLOCK
        used_n, used_u = used_n + 5, used_u + 1
    assert params.pelvis_sigma > 0 and params.hand_sigma > 0 and params.lost_fraction > 0
    assert cam._rng.bit_generator.state == ref.bit_generator.state


def test_the_envs_call_is_camera_frame():
    """``capture`` (the env's 30 Hz step) and ``frame`` give the same frames from one seed."""
    params = make_profile("paper").camera
    a = Camera(params).reset(np.random.default_rng(5))
    b = Camera(params).reset(np.random.default_rng(5))
    rng = np.random.default_rng(0)
    for k in range(300):
        hand, pelvis = rng.normal(size=3), rng.normal(size=2)
        out = a.capture(k / 30.0, hand, pelvis)
        obs = b.frame(k / 30.0, {"pelvis": pelvis, "hand": hand})
        assert out[:3] == obs.points["hand"].tolist() and out[3:5] == obs.points["pelvis"].tolist()
        assert obs.tracked == bool(a.state[cf.OUT + cf.R_TRACKED])
        assert obs.t_capture == a.state[cf.OUT + cf.R_T]
    assert np.array_equal(a.state, b.state)


def test_a_keypoint_that_changes_dimension_restarts_its_noise():
    """The noise of a keypoint whose dimension changes is drawn afresh (sigma z), not carried
    (rho n + c z)."""
    params = CameraParams(**{**QUIET, "pelvis_sigma": 0.1, "pelvis_rho": 0.99})
    cam = Camera(params).reset(np.random.default_rng(2))
    p0 = cam.frame(0.0, {"pelvis": np.zeros(2)}).points["pelvis"]
    p1 = cam.frame(0.1, {"pelvis": np.zeros(3)}).points["pelvis"]
    z = np.random.default_rng(2).standard_normal(5)
    np.testing.assert_array_equal(p0, 0.1 * z[:2])
    np.testing.assert_array_equal(p1, 0.1 * z[2:5])
    assert cam.frame(0.2, {}).points == {}
