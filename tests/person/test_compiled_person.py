"""The person's compiled per-step work (issue 34): targets, judgements, pose, hand, effort.

Each kernel is checked against the rule it computes: the tick targets against the keyframes and
the feed-forward's clipping, the judgement's in-place path against a PathAhead built with numpy,
the rotations against MuJoCo and numpy (to the last bits they may differ by on another BLAS), the
pose against its own invariants (the grip on a reachable target, unit quaternions), the hand
against its boundary conditions, and the effort's path deviation against ``math.hypot``.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from handover_env.person import hand_path as hp
from handover_env.person import path_ahead as pa
from handover_env.person.effort import (
    ARM_OUT,
    ARM_OUT_TIME,
    DT,
    GRIP,
    PATH_DEVIATION,
    PELVIS,
    REACH_MAX,
    SHOULDER,
    SLOTS,
    TARGET_X,
    TARGET_Y,
    track_kernel,
)
from handover_env.person.person import RATE, scripted_motion
from handover_env.person.pose import MotionPose, interp
from handover_env.person.posing import mat_mat, mat_quat, mat_vec, swing_mat
from handover_env.person.receiver_rules import PathAhead, left_behind, meet
from handover_env.person.rotations import length
from handover_env.person.skeleton import RIGHT_ARM, SEG, SEGMENTS
from handover_env.person.targets import (
    ACC_GAIN,
    ACCEL_LIMIT,
    DPOS,
    LAG,
    LAG_DT,
    PLAN_COLS,
    POS0,
    QUAT0,
    SPEED_LIMIT,
    VEL,
    plan_kernel,
    targets_kernel,
    tick_kernel,
)

S = 3


def _keys(step: np.ndarray) -> np.ndarray:
    keys = np.zeros((2, S, 7))
    keys[:, :, 3] = 1.0  # identity rotations
    keys[1, :, :3] = step
    return keys


def _ff(lag: float, acc_gain: float, speed: float = 2.0, accel: float = 30.0) -> np.ndarray:
    ff = np.zeros((S, 5))
    ff[:, LAG_DT], ff[:, LAG], ff[:, ACC_GAIN] = lag * RATE, lag, acc_gain
    ff[:, SPEED_LIMIT], ff[:, ACCEL_LIMIT] = speed, accel
    return ff


def test_without_lag_the_targets_run_from_one_keyframe_to_the_next():
    keys = _keys(np.array([0.03, -0.01, 0.02]))
    plan = np.zeros((S, PLAN_COLS))
    plan_kernel(keys, _ff(0.0, 0.0), plan)
    pos, quat = np.zeros((S, 3)), np.zeros((S, 4))
    for a in (0.0, 0.5, 1.0):
        targets_kernel(plan, a, pos, quat)
        np.testing.assert_array_equal(pos, a * keys[1, :, :3])
        np.testing.assert_array_equal(quat, keys[0, :, 3:])
    np.testing.assert_allclose(plan[:, VEL:VEL + 3], keys[1, :, :3] * RATE)


def test_the_feed_forward_leads_by_lag_times_velocity_clipped_to_a_human_speed():
    lag = 0.05
    slow = np.array([0.02, 0.0, 0.0])  # 0.6 m/s: led by lag * v (and by the acceleration's lead)
    plan = np.zeros((S, PLAN_COLS))
    plan_kernel(_keys(slow), _ff(lag, 0.0), plan)
    np.testing.assert_allclose(plan[:, POS0], lag * slow[0] * RATE, rtol=1e-12)
    fast = np.array([0.3, 0.0, 0.0])  # 9 m/s: led by lag * 2 m/s only
    plan = np.zeros((S, PLAN_COLS))
    plan_kernel(_keys(fast), _ff(lag, 0.0), plan)
    np.testing.assert_allclose(plan[:, POS0], lag * 2.0, rtol=1e-12)
    np.testing.assert_allclose(plan[:, DPOS], 0.3)
    accel = np.zeros((S, PLAN_COLS))
    plan_kernel(_keys(slow), _ff(0.0, 0.01, accel=1.0), accel)  # 18 m/s^2 clipped to 1
    np.testing.assert_allclose(accel[:, POS0], 0.01 * 1.0, rtol=1e-12)


def test_a_rotating_keyframe_pair_leads_the_rotation_and_keeps_its_sign():
    keys = _keys(np.zeros(3))
    half = 0.5 * 0.1  # 0.1 rad about z over the step
    keys[1, :, 3:] = -np.array([math.cos(half), 0.0, 0.0, math.sin(half)])  # the other sign
    plan = np.zeros((S, PLAN_COLS))
    plan_kernel(keys, _ff(0.05, 0.0), plan)
    lead = plan[0, QUAT0:QUAT0 + 4]
    assert lead[0] == 1.0 and lead[3] > 0.0  # turned ahead, the same way as the step's rotation
    np.testing.assert_allclose(lead[3], 0.05 * RATE * math.sin(half), rtol=1e-12)


def test_ticks_step_through_their_fractions_then_hold_the_end():
    plan = np.zeros((S, PLAN_COLS))
    plan[:, DPOS] = 1.0
    ticks = np.array([0.0, 0.25, 0.75])
    pos, quat = np.zeros((S, 3)), np.zeros((S, 4))
    seen = []
    for _ in range(3):
        tick_kernel(plan, ticks, pos, quat)
        seen.append(pos[0, 0])
    assert seen == [0.25, 0.75, 1.0] and ticks[0] == 3.0


def _motion(seed: int = 3):
    return scripted_motion(np.random.default_rng(seed), "id", None, None, None)


def test_the_judgement_builds_the_path_ahead_that_the_rules_read():
    motion = _motion()
    pose = MotionPose(motion)
    shoulder, forward = pose.shoulder_track()
    track, path = pa.track_rows(shoulder, forward)
    io = np.zeros(pa.IO_SIZE)
    io[pa.MIN_SPEED], io[pa.BEHIND], io[pa.WITHIN] = 0.4, 0.35, 1.2
    io[pa.REACH], io[pa.LEAD], io[pa.COMFORT] = 0.7, 0.8, 0.6
    rng = np.random.default_rng(0)
    for _ in range(40):
        tau, rho = rng.uniform(0.0, motion.frames - 1.0), rng.uniform(0.2, 1.0)
        obj = interp(shoulder, tau) + rng.normal(size=3) * 0.6
        vel = rng.normal(size=3) * 0.3
        io[pa.TAU], io[pa.RHO] = tau, rho
        io[pa.OBJ:pa.OBJ + 3], io[pa.OBJ_VEL:pa.OBJ_VEL + 3] = obj, vel
        io[pa.CLOSEST] = io[pa.TAKE] = -1.0
        pa.judge_kernel(track, path, io)
        f0 = int(math.floor(tau)) + 1
        frames = np.concatenate([[tau], np.arange(f0, motion.frames, dtype=np.float64)])
        ahead = PathAhead((frames - tau) / (RATE * max(rho, 0.4)),
                          np.vstack([interp(shoulder, tau), shoulder[f0:]]),
                          np.vstack([interp(forward, tau), forward[f0:]]))
        m = meet(obj, vel, ahead, 0.7, 0.8, 0.6)
        assert (io[pa.LEFT] > 0.0) == left_behind(obj, ahead, 0.35, 1.2)
        assert io[pa.MEETING:pa.MEETING + 5].tolist() == [m.time, m.distance, m.closest, m.take,
                                                          float(m.reachable)]


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, q / np.linalg.norm(q))
    return m


def test_rotations_agree_with_mujoco_and_numpy():
    rng = np.random.default_rng(1)
    for _ in range(500):
        m = _rotation(rng)
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, m)
        q *= -1.0 if q[0] < 0 else 1.0
        np.testing.assert_array_max_ulp(np.array(mat_quat(tuple(m))), q, maxulp=2)
        b, x = rng.normal(size=9), rng.normal(size=3)
        mm, mv = np.array(mat_mat(tuple(m), tuple(b))), np.array(mat_vec(tuple(m), *x))
        np.testing.assert_allclose(mm, (m.reshape(3, 3) @ b.reshape(3, 3)).ravel(), atol=1e-14)
        np.testing.assert_allclose(mv, m.reshape(3, 3) @ x, atol=1e-14)
        u, v = rng.normal(size=3), rng.normal(size=3)
        r = np.array(swing_mat(*u, *v)).reshape(3, 3)
        np.testing.assert_allclose(r @ (u / length(u)), v / length(v), atol=1e-12)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)


def test_the_pose_reaches_a_target_in_reach_and_keeps_unit_quaternions():
    motion = _motion()
    pose = MotionPose(motion)
    rng = np.random.default_rng(2)
    for _ in range(30):
        tau = rng.uniform(0.0, motion.frames - 1.0)
        shoulder, _, _ = pose.body_frame(tau, 1.0)
        d = rng.normal(size=3)
        target = shoulder + d / length(d) * 0.6 * pose.arm_reach
        origin, quat = pose.at(tau, target, swing_arm=True)
        np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-12)
        hand = quat[SEG["hand_r"]]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, hand)
        grip = origin[SEG["hand_r"]] + rot.reshape(3, 3) @ pose.grip_local
        np.testing.assert_allclose(grip, target, atol=1e-9)
        # the segments the arm does not move are the motion's own
        bare, _ = pose.at(tau, None, swing_arm=False)
        legs = [i for i in range(len(SEGMENTS)) if i not in RIGHT_ARM and
                SEGMENTS[i].name.startswith(("thigh", "shank"))]
        np.testing.assert_array_equal(origin[legs], bare[legs])


def test_the_hand_arrives_when_its_time_is_up_and_stays_within_the_arm():
    motion = _motion()
    pose = MotionPose(motion)
    io = np.zeros(hp.IO_SIZE)
    cfg = type("Cfg", (), dict(close_time=0.25, approach_distance=0.12, approach_height=0.04,
                               hold_time=0.63, pull_distance=0.2, pull_time=0.5,
                               carry_forward=0.1))()
    hp.hand_settings(io, cfg, 0.75, pose.arm_reach, RATE, 0.3, 0.35, (0.3, -0.15, -0.15), 0.1)
    tau = 30.0
    shoulder, _, _ = pose.body_frame(tau, 1.0)
    io[hp.STATE], io[hp.TAU], io[hp.RHO], io[hp.NOW], io[hp.DT] = hp.PRESENTING, tau, 1.0, 0.0, 1.0
    io[hp.X:hp.X + 3] = shoulder + np.array([0.0, 0.0, -0.5])
    io[hp.GOAL_TIME] = 0.0  # time is up: the hand is at the goal, at rest relative to it
    hp.hand_kernel(pose.rows, pose.io, io)
    torso, _ = pose.arm_rotations(tau, motion.arm_swing)
    np.testing.assert_allclose(io[hp.X:hp.X + 3], shoulder + torso @ [0.3, -0.15, -0.15],
                               atol=1e-12)
    np.testing.assert_array_equal(io[hp.A:hp.A + 3], 0.0)
    io[hp.STATE], io[hp.GRASP:hp.GRASP + 3] = hp.REACHING, shoulder + [3.0, 0.0, 0.0]
    io[hp.GOAL_TIME], io[hp.SIDE] = 0.0, 1.0
    hp.hand_kernel(pose.rows, pose.io, io)  # out of reach: held at the arm's length, goal put off
    assert length(io[hp.X:hp.X + 3] - shoulder) == pytest.approx(pose.arm_reach, abs=1e-12)
    assert io[hp.GOAL_TIME] == pytest.approx(0.25)


def _holding_io(pose, tau: float, rel) -> np.ndarray:
    io = np.zeros(hp.IO_SIZE)
    cfg = type("Cfg", (), dict(close_time=0.25, approach_distance=0.12, approach_height=0.04,
                               hold_time=0.63, pull_distance=0.2, pull_time=0.5,
                               carry_forward=0.1))()
    hp.hand_settings(io, cfg, 0.75, pose.arm_reach, RATE, 0.3, 0.35, (0.3, -0.15, -0.15), 0.1)
    # a person standing (speed factor 0): the pelvis-fixed hold does not move on
    io[hp.STATE], io[hp.TAU], io[hp.RHO], io[hp.NOW], io[hp.DT] = hp.HOLDING, tau, 0.0, 0.5, 1.0
    io[hp.T_GRASP], io[hp.HOLD_REL:hp.HOLD_REL + 3] = 0.0, rel
    io[hp.GOAL_TIME] = 0.0  # a step of 1 s > the hold's tracking time: the hand is at its goal
    return io


def test_a_held_object_leaves_the_gripper_by_its_open_side():
    """avoid_gripper: the hold's goal (a point fixed to the pelvis) is kept no deeper along the
    gripper's axis than at the grasp, and from the release on OUT_DISTANCE farther out."""
    motion = _motion()
    pose = MotionPose(motion)
    tau, rel = 30.0, np.array([0.25, -0.2, 0.4])  # 0.3 m ahead of the right shoulder
    io = _holding_io(pose, tau, rel)
    hp.hand_kernel(pose.rows, pose.io, io)
    free = io[hp.X:hp.X + 3].copy()  # no gripper known: the pelvis-fixed hold itself
    shoulder, _, _ = pose.body_frame(tau, 1.0)
    assert length(free - shoulder) < pose.arm_reach - 0.2  # room to move without the arm's clamp
    axis = np.array([*(shoulder - free)[:2], 0.0])  # a gripper whose fingertips face the person
    axis /= length(axis)
    for released, extra in ((False, 0.0), (True, 0.1)):
        io = _holding_io(pose, tau, rel)
        io[hp.HAS_GRIP], io[hp.GRIP_AXIS:hp.GRIP_AXIS + 3] = 1.0, axis
        io[hp.TCP:hp.TCP + 3] = free - 0.05 * axis  # the hold would sit 5 cm out of the TCP
        io[hp.DEPTH] = 0.12  # but the hand took the object 12 cm out
        if released:
            io[hp.T_OUT] = 0.4
        hp.hand_kernel(pose.rows, pose.io, io)
        moved = io[hp.X:hp.X + 3] - free
        assert (io[hp.X:hp.X + 3] - io[hp.TCP:hp.TCP + 3]) @ axis == pytest.approx(0.12 + extra)
        np.testing.assert_allclose(moved, (0.07 + extra) * axis, atol=1e-12)  # only along it
    io = _holding_io(pose, tau, rel)  # deep enough already: the hold is left as it is
    io[hp.HAS_GRIP], io[hp.GRIP_AXIS:hp.GRIP_AXIS + 3] = 1.0, axis
    io[hp.TCP:hp.TCP + 3], io[hp.DEPTH] = free - 0.2 * axis, 0.12
    hp.hand_kernel(pose.rows, pose.io, io)
    np.testing.assert_array_equal(io[hp.X:hp.X + 3], free)


def test_the_effort_tracks_arm_time_reach_and_the_pelvis_offset():
    xpos, site = np.zeros((3, 3)), np.zeros((1, 3))
    xpos[1] = [0.0, 0.0, 1.4]  # shoulder
    site[0] = [0.3, 0.4, 1.4]  # grip, 0.5 m away
    xpos[2] = [1.0, 2.0, 0.9]  # pelvis
    acc = np.zeros(SLOTS)
    acc[SHOULDER], acc[GRIP], acc[PELVIS] = 1, 0, 2
    acc[ARM_OUT], acc[DT], acc[TARGET_X], acc[TARGET_Y] = 1.0, 0.1, 1.3, 1.6
    track_kernel(xpos, site, acc)
    acc[ARM_OUT] = 0.0
    track_kernel(xpos, site, acc)
    assert acc[ARM_OUT_TIME] == 0.1 and acc[REACH_MAX] == pytest.approx(0.5)
    assert acc[PATH_DEVIATION] == math.hypot(1.0 - 1.3, 2.0 - 1.6)
