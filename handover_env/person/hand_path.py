"""The modelled hand's path, advanced one env step in one compiled call.

:func:`hand_kernel` is the arithmetic of :meth:`handover_env.person.receiver.Receiver`'s hand:
from the person's state it sets the hand's goal and the time left to reach it, then moves the
hand one env step along the minimum-jerk path re-planned toward where the goal will be
(:func:`handover_env.person.min_jerk.quintic_step`, Hoff & Arbib 1993), never beyond the arm's
reach. The goals, by state:

* **reaching**: the object's grasp point, approached from the person's side (or from the
  fingertips' side of a gripper that faces them) and a little above, closing in over the last
  ``close_time``; an object still out of reach holds the hand ready in front of it;
* **holding**, for ``hold_time`` after the grasp: a point fixed to the pelvis (the shared hold
  of the recordings), settled onto over at least ``HOLD_TRACKING``;
* **holding**, until the object is clear of the gripper: drawn toward the body at the height it
  is held, no closer than ``CARRY_CLEARANCE`` to the pelvis axis;
* **holding** after that: the carry pose, ``carry_forward`` ahead of the walking swing;
* **presenting / presented** (static handover): ``PRESENT_OFFSET`` from the shoulder;
* **passed** (the object left behind): back to the walking swing over ``pull_time``.

The body's frames come from the motion rows of :func:`handover_env.person.posing.motion_rows`
and the products are numpy's (:mod:`handover_env.person.posing`), so the hand is bit for bit the
numpy one (:func:`handover_env.compiled.kernel`).
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.compiled import kernel
from handover_env.person.min_jerk import quintic_step
from handover_env.person.posing import (
    ELBOW,
    GRIP,
    SEGS,
    SHOULDER,
    TORSO,
    WRIST,
    interp_mat,
    mat_mat,
    mat_vec,
    norm3,
    quat_mat,
)

#: The hand's state codes (``io[STATE]``).
REACHING, HOLDING, PRESENTING, PASSED = 1, 2, 3, 4
# Slots of the hand's io array: per call, then in / out, then the person's settings.
STATE, TAU, RHO, NOW, DT, T_GRASP, CLEAR, SIDE, HAS_AXIS = 0, 1, 2, 3, 4, 5, 6, 7, 8
AXIS, GRASP, OBJ_VEL, HOLD_REL = 9, 12, 15, 18  # 3 each
X, V, A, GOAL_TIME = 21, 24, 27, 30  # the hand's state (3 each) and its goal time (in / out)
CLOSE_TIME, APPROACH_DISTANCE, APPROACH_HEIGHT, HOLD_TIME = 31, 32, 33, 34
PULL_DISTANCE, PULL_TIME, CARRY_FORWARD, MAX_REACH, ARM_REACH = 35, 36, 37, 38, 39
RATE_HZ, HOLD_TRACK, CLEARANCE, PRESENT = 40, 41, 42, 43  # PRESENT: 3
# The gripper the held object is drawn out of (``avoid_gripper``): its approach axis when it last
# held (3), its TCP now (3), the hand's depth along that axis at the grasp, whether they are set,
# when the draw-out started (inf: not yet) and how far out it goes.
GRIP_AXIS, TCP, DEPTH, HAS_GRIP, T_OUT, OUT_DISTANCE = 46, 49, 52, 53, 54, 55
IO_SIZE = 56


@kernel
def _at(tau: float, n_frames: int) -> tuple[int, float]:
    """The frame i and fraction a of ``pose.interp`` at tau (clamped)."""
    f = min(max(tau, 0.0), n_frames - 1.0)
    i = min(int(f), n_frames - 2)
    return i, f - i


@kernel
def _lerp(motion: np.ndarray, i: int, a: float, k: int) -> float:
    return motion[i, k] * (1.0 - a) + motion[i + 1, k] * a


@kernel
def _torso(motion: np.ndarray, pose: np.ndarray, i: int,
           a: float) -> tuple[float, float, float, float, float, float, float, float, float]:
    """The torso's rotation at (i, a): its interpolated quaternion, normalised."""
    segs, t = int(pose[SEGS]), int(pose[TORSO])
    k = 3 * segs + 4 * t
    q0, q1 = _lerp(motion, i, a, k), _lerp(motion, i, a, k + 1)
    q2, q3 = _lerp(motion, i, a, k + 2), _lerp(motion, i, a, k + 3)
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return quat_mat(q0 / n, q1 / n, q2 / n, q3 / n)


@kernel
def _shoulder(motion: np.ndarray, pose: np.ndarray, i: int, a: float,
              torso: tuple) -> tuple[float, float, float]:
    """The right shoulder at (i, a) (``MotionPose.body_frame``)."""
    t = int(pose[TORSO])
    r0, r1, r2 = mat_vec(torso, pose[SHOULDER], pose[SHOULDER + 1], pose[SHOULDER + 2])
    return (_lerp(motion, i, a, 3 * t) + r0, _lerp(motion, i, a, 3 * t + 1) + r1,
            _lerp(motion, i, a, 3 * t + 2) + r2)


@kernel
def _swing_grip(motion: np.ndarray, pose: np.ndarray, tau: float) -> tuple[float, float, float]:
    """The grip point of the walking arm swing at tau (``MotionPose.grip_from_arm``)."""
    i, a = _at(tau, motion.shape[0])
    torso = _torso(motion, pose, i, a)
    base = 7 * int(pose[SEGS])
    upper = mat_mat(torso, interp_mat(motion, i, a, base))
    fore = mat_mat(torso, interp_mat(motion, i, a, base + 9))
    hand = mat_mat(torso, interp_mat(motion, i, a, base + 18))
    s0, s1, s2 = _shoulder(motion, pose, i, a, torso)
    e0, e1, e2 = mat_vec(upper, pose[ELBOW], pose[ELBOW + 1], pose[ELBOW + 2])
    e0, e1, e2 = s0 + e0, s1 + e1, s2 + e2
    w0, w1, w2 = mat_vec(fore, pose[WRIST], pose[WRIST + 1], pose[WRIST + 2])
    w0, w1, w2 = e0 + w0, e1 + w1, e2 + w2
    g0, g1, g2 = mat_vec(hand, pose[GRIP], pose[GRIP + 1], pose[GRIP + 2])
    return w0 + g0, w1 + g1, w2 + g2


@kernel
def _pelvis(motion: np.ndarray, io: np.ndarray, tau: float,
            rel: tuple[float, float, float]) -> tuple[float, float, float, float, float, float]:
    """A point ``rel`` fixed to the nominal pelvis at tau, and the pelvis's velocity
    (``MotionPose.pelvis``)."""
    n_frames = motion.shape[0]
    i, a = _at(tau, n_frames)
    segs = (motion.shape[1] - 28) // 7
    k = 3 * segs
    q0, q1 = _lerp(motion, i, a, k), _lerp(motion, i, a, k + 1)
    q2, q3 = _lerp(motion, i, a, k + 2), _lerp(motion, i, a, k + 3)
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    rot = quat_mat(q0 / n, q1 / n, q2 / n, q3 / n)
    j = min(int(tau), n_frames - 2)
    scale = io[RATE_HZ]
    v0 = (motion[j + 1, 0] - motion[j, 0]) * scale * io[RHO]
    v1 = (motion[j + 1, 1] - motion[j, 1]) * scale * io[RHO]
    v2 = (motion[j + 1, 2] - motion[j, 2]) * scale * io[RHO]
    r0, r1, r2 = mat_vec(rot, rel[0], rel[1], rel[2])
    return (_lerp(motion, i, a, 0) + r0, _lerp(motion, i, a, 1) + r1, _lerp(motion, i, a, 2) + r2,
            v0, v1, v2)


@kernel
def _out_of_gripper(io: np.ndarray, goal: tuple, goal_v: tuple) -> tuple[tuple, tuple]:
    """A held object not yet out of the gripper leaves it by the open side: the hand's goal
    comes no deeper along the gripper's approach axis (from its TCP) than the hand was at the
    grasp, and from the release on ``OUT_DISTANCE`` farther out; it does not move toward the
    gripper's palm."""
    a0, a1, a2 = io[GRIP_AXIS], io[GRIP_AXIS + 1], io[GRIP_AXIS + 2]
    depth = (goal[0] - io[TCP]) * a0 + (goal[1] - io[TCP + 1]) * a1 + (goal[2] - io[TCP + 2]) * a2
    lack = io[DEPTH] + (io[OUT_DISTANCE] if io[NOW] >= io[T_OUT] else 0.0) - depth
    if lack <= 0.0:
        return goal, goal_v
    va = goal_v[0] * a0 + goal_v[1] * a1 + goal_v[2] * a2
    va = min(va, 0.0)
    return ((goal[0] + lack * a0, goal[1] + lack * a1, goal[2] + lack * a2),
            (goal_v[0] - va * a0, goal_v[1] - va * a1, goal_v[2] - va * a2))


@kernel
def hand_kernel(motion: np.ndarray, pose: np.ndarray, io: np.ndarray) -> None:
    """Advance the hand ``io[X:X + 9]`` (position, velocity, acceleration) one env step of
    ``io[DT]`` at playback position ``io[TAU]`` in state ``io[STATE]`` (module docstring);
    ``io[GOAL_TIME]`` is put off while a reached-for object is out of reach."""
    tau, rho, now = io[TAU], io[RHO], io[NOW]
    state = int(io[STATE])
    i, a = _at(tau, motion.shape[0])
    torso = _torso(motion, pose, i, a)
    s0, s1, s2 = _shoulder(motion, pose, i, a, torso)
    held = min(io[T_GRASP] + io[HOLD_TIME], io[T_OUT])
    scale = io[RATE_HZ]
    if state == REACHING:
        g0, g1, g2 = io[GRASP], io[GRASP + 1], io[GRASP + 2]
        w0, w1, w2 = s0 - g0, s1 - g1, 0.0  # from the person's side, horizontally
        if io[HAS_AXIS] > 0.0:  # or from the fingertips' side of a gripper facing them
            x0, x1, x2 = io[AXIS], io[AXIS + 1], 0.0
            if x0 * w0 + x1 * w1 + x2 * w2 > 0.0:
                w0, w1, w2 = x0, x1, x2
        norm = norm3(w0, w1, w2)
        if norm3(g0 - s0, g1 - s1, g2 - s2) > io[MAX_REACH]:
            io[GOAL_TIME] = max(io[GOAL_TIME], now + io[CLOSE_TIME])
        w = min(max((io[GOAL_TIME] - now) / io[CLOSE_TIME], 0.0), 1.0)
        w = w * w * (3.0 - 2.0 * w)
        if norm > 1e-6:
            f = io[APPROACH_DISTANCE] * w / norm
            o0, o1 = w0 * f, w1 * f
        else:
            o0, o1 = 0.0, 0.0
        o2 = io[SIDE] * io[APPROACH_HEIGHT] * w
        goal = (g0 + o0, g1 + o1, g2 + o2)
        goal_v = (io[OBJ_VEL], io[OBJ_VEL + 1], io[OBJ_VEL + 2])
    elif state == HOLDING and now < held:
        p = _pelvis(motion, io, tau, (io[HOLD_REL], io[HOLD_REL + 1], io[HOLD_REL + 2]))
        goal, goal_v = (p[0], p[1], p[2]), (p[3], p[4], p[5])
    elif state == HOLDING and io[CLEAR] == 0.0:
        r0, r1, r2 = io[HOLD_REL], io[HOLD_REL + 1], io[HOLD_REL + 2]
        reach = math.sqrt(r0 * r0 + r1 * r1)
        f = max(reach - io[PULL_DISTANCE], min(reach, io[CLEARANCE])) / max(reach, 1e-6)
        p = _pelvis(motion, io, tau, (r0 * f, r1 * f, r2))
        goal, goal_v = (p[0], p[1], p[2]), (p[3], p[4], p[5])
    elif state == PRESENTING:
        r0, r1, r2 = mat_vec(torso, io[PRESENT], io[PRESENT + 1], io[PRESENT + 2])
        goal, goal_v = (s0 + r0, s1 + r1, s2 + r2), (0.0, 0.0, 0.0)
    else:  # holding and carrying, or passed: the walking swing (carried a little forward)
        p0 = _swing_grip(motion, pose, tau)
        p1 = _swing_grip(motion, pose, tau + 1.0)
        goal_v = ((p1[0] - p0[0]) * scale * rho, (p1[1] - p0[1]) * scale * rho,
                  (p1[2] - p0[2]) * scale * rho)
        if state == HOLDING:
            h = _lerp(motion, i, a, motion.shape[1] - 1)
            c = io[CARRY_FORWARD]
            goal = (p0[0] + c * math.cos(h), p0[1] + c * math.sin(h), p0[2] + c * 0.0)
        else:
            goal = p0
    if state == HOLDING and io[CLEAR] == 0.0 and io[HAS_GRIP] > 0.0:
        goal, goal_v = _out_of_gripper(io, goal, goal_v)
    if state == HOLDING and now < held:
        remaining = max(held - now, io[HOLD_TRACK])
    elif state == PASSED:
        remaining = max(io[GOAL_TIME] - now, io[PULL_TIME])
    else:
        remaining = max(io[GOAL_TIME] - now, 0.1)
    dt = io[DT]
    for c in range(3):
        x1 = goal[c] + goal_v[c] * remaining  # where the goal will be when the movement ends
        if dt >= remaining:
            io[X + c], io[V + c], io[A + c] = x1, goal_v[c], 0.0
        else:
            io[X + c], io[V + c], io[A + c] = quintic_step(
                io[X + c], io[V + c], io[A + c], x1, goal_v[c], remaining, dt)
    d0, d1, d2 = io[X] - s0, io[X + 1] - s1, io[X + 2] - s2
    dist = norm3(d0, d1, d2)
    if dist > io[ARM_REACH]:
        f = io[ARM_REACH] / dist
        io[X], io[X + 1], io[X + 2] = s0 + d0 * f, s1 + d1 * f, s2 + d2 * f


def hand_settings(io: np.ndarray, config, max_reach: float, arm_reach: float, rate: float,
                  hold_tracking: float, clearance: float, present: tuple[float, float, float],
                  out_distance: float) -> None:
    """Write a person's settings (a :class:`~handover_env.person.settings.ReceiverConfig` and
    their reach) into the hand's io array."""
    io[CLOSE_TIME], io[APPROACH_DISTANCE] = config.close_time, config.approach_distance
    io[APPROACH_HEIGHT], io[HOLD_TIME] = config.approach_height, config.hold_time
    io[PULL_DISTANCE], io[PULL_TIME] = config.pull_distance, config.pull_time
    io[CARRY_FORWARD], io[MAX_REACH], io[ARM_REACH] = config.carry_forward, max_reach, arm_reach
    io[RATE_HZ], io[HOLD_TRACK], io[CLEARANCE] = rate, hold_tracking, clearance
    io[PRESENT:PRESENT + 3] = present
    io[HAS_GRIP], io[T_OUT], io[OUT_DISTANCE] = 0.0, math.inf, out_distance
