"""The person's kinematics: rotations, retargeting recorded joints onto the rigid body, gait, arm
IK."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from handover_env.person import motion as rm
from handover_env.person import trajectory
from handover_env.person.gait import arm_pose, walking_pose
from handover_env.person.rotations import length, mat_to_quat, swing, triad, yaw_matrix
from handover_env.person.skeleton import (
    N_SEGMENTS,
    SEG,
    SEGMENTS,
    TEMPLATE,
    BodyDims,
    BodyPose,
    J,
    forward_kinematics,
    joints_of,
    measure_dims,
    retarget,
)


def _random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out = np.empty((n, 3, 3))
    for k in range(n):
        m = np.empty(9)
        mujoco.mju_quat2Mat(m, q[k])
        out[k] = m.reshape(3, 3)
    return out


def test_swing_is_the_smallest_rotation_taking_a_onto_b():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    r = swing(a, b)
    np.testing.assert_allclose(
        np.einsum("nij,nj->ni", r, a / np.linalg.norm(a, axis=1, keepdims=True)),
        b / np.linalg.norm(b, axis=1, keepdims=True),
        atol=1e-9,
    )
    np.testing.assert_allclose(
        r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), r.shape), atol=1e-9
    )
    # Smallest: the rotation angle equals the angle between a and b, about an axis normal to both.
    angle = np.arccos(np.clip((np.trace(r, axis1=1, axis2=2) - 1) / 2, -1, 1))
    between = np.arccos(
        np.clip(np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1), -1, 1)
    )
    np.testing.assert_allclose(angle, between, atol=1e-7)


def test_mat_to_quat_matches_mujoco():
    rots = _random_rotations(np.random.default_rng(1), 40)
    q = mat_to_quat(rots)
    for k in range(40):
        ref = np.empty(4)
        mujoco.mju_mat2Quat(ref, rots[k].reshape(9))
        ref *= 1.0 if ref[0] >= 0 else -1.0
        np.testing.assert_allclose(q[k], ref, atol=1e-9)


def test_triad_and_yaw():
    r = triad(np.array([0.0, 0.0, 2.0]), np.array([0.3, 1.0, 0.0]))
    np.testing.assert_allclose(r[:, 2], [0, 0, 1], atol=1e-12)
    assert r[:, 1] @ np.array([0.3, 1.0, 0.0]) > 0 and abs(np.linalg.det(r) - 1) < 1e-12
    np.testing.assert_allclose(
        yaw_matrix(math.pi / 2) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12
    )


def test_retarget_recovers_a_rigid_pose():
    """Joints made by the rigid model from known rotations retarget to those rotations."""
    dims = BodyDims.from_height(1.8)
    rng = np.random.default_rng(3)
    rot = np.empty((N_SEGMENTS, 3, 3))
    rot[0] = yaw_matrix(2.7)
    for i, s in enumerate(SEGMENTS[1:], start=1):
        # Moderate joint rotations (a walking or reaching posture) about random axes.
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        ang = rng.uniform(-0.6, 0.6)
        m = np.empty(9)
        mujoco.mju_quat2Mat(m, np.r_[math.cos(ang / 2), axis * math.sin(ang / 2)])
        rot[i] = rot[s.parent] @ m.reshape(3, 3)
    pelvis = np.array([0.4, -0.9, 0.95])
    origin = forward_kinematics(pelvis, rot, dims)
    pose = retarget(joints_of(BodyPose(origin, rot), dims), dims)
    np.testing.assert_allclose(pose.origin, origin, atol=1e-9)
    # Bone directions agree (the twist of a limb about its own bone is not observable).
    for i, s in enumerate(SEGMENTS):
        if s.tip >= 0:
            want = rot[i] @ dims.local(s.tip, i)
            got = pose.rot[i] @ dims.local(s.tip, i)
            np.testing.assert_allclose(got, want, atol=1e-9)


def test_measure_dims_keeps_lengths_and_rejects_bad_input():
    dims = BodyDims.from_height(1.7)
    joints = np.stack([TEMPLATE * (1.7 / 1.725) + [1.0, -0.9, dims.pelvis_z]] * 5)
    measured = measure_dims(joints)
    np.testing.assert_allclose(
        np.linalg.norm(measured.bones, axis=1), np.linalg.norm(dims.bones, axis=1), atol=1e-9
    )
    assert measured.height == pytest.approx(1.7, abs=0.01)
    with pytest.raises(ValueError, match="shape"):
        measure_dims(np.zeros((5, 33, 3)))
    with pytest.raises(ValueError, match="NaN"):
        retarget(np.full((34, 3), np.nan), dims)
    with pytest.raises(ValueError, match="height"):
        BodyDims.from_height(3.0)


def test_swing_of_one_pair_is_the_batched_swing_bit_for_bit():
    # One pair (a pose's arm, every env step) takes a float path; it must not move a bit.
    rng = np.random.default_rng(3)
    a = rng.normal(size=(2000, 3)) * rng.lognormal(size=(2000, 1))
    b = rng.normal(size=(2000, 3)) * rng.lognormal(size=(2000, 1))
    b[::5] = 2.0 * a[::5] + 1e-9 * rng.normal(size=(400, 3))  # nearly parallel
    batched = swing(a, b)
    assert all(np.array_equal(swing(a[i], b[i]), batched[i]) for i in range(len(a)))
    one = swing(a[0].astype(np.float32), b[0].astype(np.float32))  # not float64: numpy's path
    np.testing.assert_allclose(one, batched[0], atol=1e-6)


def test_length_is_numpys_norm_bit_for_bit():
    rng = np.random.default_rng(4)
    x = rng.normal(size=(3000, 4)) * rng.lognormal(size=(3000, 1))
    for v in x:  # contiguous float64: the fast path
        assert length(v[:3]) == np.linalg.norm(v[:3]) and length(v) == np.linalg.norm(v)
    for v in (x[:5, 1], x[0].astype(np.float32), [3.0, 4.0], np.zeros(3)):  # the others
        assert length(v) == np.linalg.norm(v)
    assert isinstance(length(x[0]), float)


def test_walking_pose_swings_legs_in_antiphase_and_follows_the_track():
    walker = rm.sample_walker(np.random.default_rng(0), "id")
    traj = trajectory.base_trajectory(walker)
    dims = BodyDims.from_height(walker.height)
    pose = walking_pose(traj, dims)
    np.testing.assert_allclose(pose.origin[:, 0, :2], traj.xy, atol=1e-12)
    ankles_r = pose.origin[:, SEG["shank_r"]] + np.einsum(
        "tij,j->ti", pose.rot[:, SEG["shank_r"]], dims.local(J["RIGHT_ANKLE"], SEG["shank_r"])
    )
    ankles_l = pose.origin[:, SEG["shank_l"]] + np.einsum(
        "tij,j->ti", pose.rot[:, SEG["shank_l"]], dims.local(J["LEFT_ANKLE"], SEG["shank_l"])
    )
    fwd = np.stack([np.cos(traj.heading), np.sin(traj.heading)], axis=1)
    gap = np.sum((ankles_r - ankles_l)[:, :2] * fwd, axis=1)
    # The feet alternate: the right ankle is ahead half the time, behind the other half.
    assert 0.25 < np.mean(gap > 0) < 0.75 and np.ptp(gap) > 0.3


def test_arm_pose_puts_the_grip_on_a_reachable_target():
    dims = BodyDims.from_height(1.75)
    torso = yaw_matrix(math.pi)
    shoulder = np.array([1.0, -0.7, 1.43])
    for target, level in ((np.array([0.6, -0.55, 1.35]), np.array([-1.0, 0.2, 0.0])),
                          (np.array([0.75, -0.5, 1.1]), None)):
        up, fore, hand = arm_pose(shoulder, torso, target, dims, level)
        elbow = shoulder + up @ dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"])
        wrist = elbow + fore @ dims.local(J["RIGHT_WRIST"], SEG["forearm_r"])
        grip = wrist + hand @ dims.grip("r")
        np.testing.assert_allclose(grip, target, atol=1e-6)
        for r in (up, fore, hand):
            np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
        assert elbow[2] < shoulder[2]  # the elbow hangs below the shoulder
    # Out of reach: the arm points at the target, straight.
    up, fore, hand = arm_pose(shoulder, torso, shoulder + [-2.0, 0, 0], dims)
    elbow = shoulder + up @ dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"])
    assert elbow[0] < shoulder[0] - 0.2
