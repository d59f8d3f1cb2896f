"""The person's whole body at a playback position, posed in one compiled call.

:func:`pose_kernel` is :meth:`handover_env.person.pose.MotionPose.at`'s arithmetic: the nominal
motion interpolated at the fractional frame ``tau``, the trunk turned and leaned toward a far hand
target (:meth:`~handover_env.person.pose.MotionPose.lean_toward`'s rule), the right arm posed to
the target by two-link inverse kinematics (:func:`arm_kernel`, the rule of
:func:`handover_env.person.gait.arm_pose`) or in its walking swing, and the arm's rotations turned
into quaternions as MuJoCo's ``mju_mat2Quat`` does (:func:`mat_quat`). It runs once per env step
(:func:`handover_env.compiled.kernel`: IEEE arithmetic in the order written, no reassociation).

The small products are summed as numpy sums them, so the pose is bit for bit the numpy one:
a 3x3 matrix times a 3x3 matrix or a 3-vector is OpenBLAS's (:func:`mat_mat`, :func:`mat_vec`:
numpy's ``matmul`` hands both to OpenBLAS, whose Haswell kernels fuse the multiply-adds, see
:func:`handover_env.kernel_math.fma`), the norm of a vector is a plain sum of squares left to
right (OpenBLAS's ``ddot`` on 3 or 4 numbers, numpy's row reductions), and sines, cosines and
square roots are the C library's, as Python's ``math`` calls them.

Layouts: a 3x3 matrix is a 9-tuple, row-major; the motion is one row per frame (:func:`motion_rows`)
and the person's constants and the call's inputs are the slots of one array (``io``, see
:class:`~handover_env.person.pose.MotionPose`).
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.compiled import kernel
from handover_env.kernel_math import fma

Mat3 = tuple[float, float, float, float, float, float, float, float, float]

# Slots of the pose's io array (filled by MotionPose; inputs first, then the person's constants).
TAU, HAND, HAS_HAND, SWING_ARM = 0, 1, 4, 5
SHOULDER, ELBOW, WRIST, GRIP, REST_LOWER = 6, 9, 12, 15, 18  # local vectors (3 each)
STRAIGHT_REACH, MAX_TURN, GRIP_LEN, L_UPPER, L_FORE, L_LOWER = 21, 22, 23, 24, 25, 26
SEGS, TORSO, ARM = 27, 28, 29  # segment count, torso, right arm (3)
POLE = 32  # the elbow's pole in the torso frame (3)
UPPER = 35  # upper-body mask
IO_BASE = 35  # + one upper-body flag per segment

#: The elbow's pole in the torso frame (x forward, y left, z up) with the person switch
#: ``recorded_elbow`` (on by default): the direction in which the recorded receivers held the
#: elbow off their shoulder-wrist line at the transfer, down and back (the calibration half's
#: normalised mean, R = 0.94 over 427 recordings: ``handover-data grasp-height``,
#: ``docs/calibration/grasp_height.md``, JSON ``elbow_pole.calibration.pooled.direction``).
ELBOW_POLE_RECORDED = (-0.566, -0.151, -0.810)
#: The pole with ``recorded_elbow`` off (the persons of benchmark protocols v1 and v2): down and
#: out to the right, which swings a folded arm's elbow out to the side.
ELBOW_POLE_OUT = (0.0, -0.35, -1.0)


@kernel
def mat_vec(m: Mat3, x0: float, x1: float, x2: float) -> tuple[float, float, float]:
    """``M @ x`` as numpy's ``matmul`` gives it (OpenBLAS ``dgemv_t``: per row
    ``fma(m2, x2, fma(m0, x0, m1 x1))``)."""
    return (fma(m[2], x2, fma(m[0], x0, m[1] * x1)),
            fma(m[5], x2, fma(m[3], x0, m[4] * x1)),
            fma(m[8], x2, fma(m[6], x0, m[7] * x1)))


@kernel
def mat_mat(a: Mat3, b: Mat3) -> Mat3:
    """``A @ B`` as numpy's ``matmul`` gives it (OpenBLAS ``dgemm``: per entry
    ``fma(a2, b2, fma(a1, b1, a0 b0))``)."""
    return (fma(a[2], b[6], fma(a[1], b[3], a[0] * b[0])),
            fma(a[2], b[7], fma(a[1], b[4], a[0] * b[1])),
            fma(a[2], b[8], fma(a[1], b[5], a[0] * b[2])),
            fma(a[5], b[6], fma(a[4], b[3], a[3] * b[0])),
            fma(a[5], b[7], fma(a[4], b[4], a[3] * b[1])),
            fma(a[5], b[8], fma(a[4], b[5], a[3] * b[2])),
            fma(a[8], b[6], fma(a[7], b[3], a[6] * b[0])),
            fma(a[8], b[7], fma(a[7], b[4], a[6] * b[1])),
            fma(a[8], b[8], fma(a[7], b[5], a[6] * b[2])))


@kernel
def norm3(x0: float, x1: float, x2: float) -> float:
    """|x| (:func:`handover_env.person.rotations.length`'s value)."""
    return math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)


@kernel
def quat_mat(w: float, x: float, y: float, z: float) -> Mat3:
    """:func:`handover_env.person.pose.quat_to_mat` of a unit quaternion."""
    return (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))


@kernel
def mat_quat(m: Mat3) -> tuple[float, float, float, float]:
    """The unit quaternion (w >= 0) of a rotation matrix: MuJoCo's ``mju_mat2Quat`` (the largest
    of the four components from the diagonal, the others from the off-diagonal, then
    ``mju_normalize4``), then the sign flip of :func:`handover_env.person.rotations.mat_to_quat`."""
    if m[0] + m[4] + m[8] > 0:
        w = 0.5 * math.sqrt(1 + m[0] + m[4] + m[8])
        x = 0.25 * (m[7] - m[5]) / w
        y = 0.25 * (m[2] - m[6]) / w
        z = 0.25 * (m[3] - m[1]) / w
    elif m[0] > m[4] and m[0] > m[8]:
        x = 0.5 * math.sqrt(1 + m[0] - m[4] - m[8])
        w = 0.25 * (m[7] - m[5]) / x
        y = 0.25 * (m[1] + m[3]) / x
        z = 0.25 * (m[2] + m[6]) / x
    elif m[4] > m[8]:
        y = 0.5 * math.sqrt(1 - m[0] + m[4] - m[8])
        w = 0.25 * (m[2] - m[6]) / y
        x = 0.25 * (m[1] + m[3]) / y
        z = 0.25 * (m[5] + m[7]) / y
    else:
        z = 0.5 * math.sqrt(1 - m[0] - m[4] + m[8])
        w = 0.25 * (m[3] - m[1]) / z
        x = 0.25 * (m[2] + m[6]) / z
        y = 0.25 * (m[5] + m[7]) / z
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if norm < 1e-15:  # mjMINVAL
        w, x, y, z = 1.0, 0.0, 0.0, 0.0
    elif abs(norm - 1) > 1e-15:
        inv = 1 / norm
        w, x, y, z = w * inv, x * inv, y * inv, z * inv
    if w < 0:
        return -w, -x, -y, -z
    return w, x, y, z


@kernel
def swing_mat(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> Mat3:
    """The smallest rotation taking direction ``a`` onto direction ``b`` (Rodrigues):
    :func:`handover_env.person.rotations.swing` of one pair, ``I + [v]x + [v]x^2 / (1 + c)``."""
    na = max(math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), 1e-12)
    a0, a1, a2 = a0 / na, a1 / na, a2 / na
    nb = max(math.sqrt(b0 * b0 + b1 * b1 + b2 * b2), 1e-12)
    b0, b1, b2 = b0 / nb, b1 / nb, b2 / nb
    v0, v1, v2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    c = a0 * b0 + a1 * b1 + a2 * b2
    vx = (0.0, -v2, v1, v2, 0.0, -v0, -v1, v0, 0.0)
    vv = mat_mat(vx, vx)
    k = 1.0 / max(1.0 + c, 1e-9)
    return ((1.0 + vx[0]) + vv[0] * k, (0.0 + vx[1]) + vv[1] * k, (0.0 + vx[2]) + vv[2] * k,
            (0.0 + vx[3]) + vv[3] * k, (1.0 + vx[4]) + vv[4] * k, (0.0 + vx[5]) + vv[5] * k,
            (0.0 + vx[6]) + vv[6] * k, (0.0 + vx[7]) + vv[7] * k, (1.0 + vx[8]) + vv[8] * k)


@kernel
def arm_kernel(io: np.ndarray, shoulder: tuple[float, float, float], torso: Mat3,
               grip: tuple[float, float, float], level: bool,
               hand_dir: tuple[float, float, float]) -> tuple[Mat3, Mat3, Mat3]:
    """World rotations of the right upper arm, forearm and hand that put the grip point at
    ``grip`` (the rule of :func:`handover_env.person.gait.arm_pose`; with ``level`` the hand
    points along ``hand_dir``, else it stays in line with the forearm). ``io`` holds the arm's
    rest vectors and lengths (the slots above)."""
    s0, s1, s2 = shoulder
    g0, g1, g2 = grip
    if level:
        n = max(norm3(hand_dir[0], hand_dir[1], hand_dir[2]), 1e-9)
        h0, h1, h2 = hand_dir[0] / n, hand_dir[1] / n, hand_dir[2] / n
        r0, r1, r2 = io[WRIST], io[WRIST + 1], io[WRIST + 2]
        e0, e1, e2 = g0 - io[GRIP_LEN] * h0, g1 - io[GRIP_LEN] * h1, g2 - io[GRIP_LEN] * h2
        l2 = io[L_FORE]
    else:
        h0, h1, h2 = 0.0, 0.0, 0.0
        r0, r1, r2 = io[REST_LOWER], io[REST_LOWER + 1], io[REST_LOWER + 2]
        e0, e1, e2 = g0, g1, g2
        l2 = io[L_LOWER]
    l1 = io[L_UPPER]
    d0, d1, d2 = e0 - s0, e1 - s1, e2 - s2
    dist = norm3(d0, d1, d2)
    dist_c = min(max(dist, abs(l1 - l2) + 1e-4), (l1 + l2) * 0.9995)
    dn = max(dist, 1e-9)
    u0, u1, u2 = d0 / dn, d1 / dn, d2 / dn
    p0, p1, p2 = mat_vec(torso, io[POLE], io[POLE + 1], io[POLE + 2])
    pu = p0 * u0 + p1 * u1 + p2 * u2
    p0, p1, p2 = p0 - pu * u0, p1 - pu * u1, p2 - pu * u2
    if norm3(p0, p1, p2) < 1e-6:
        p0, p1, p2 = mat_vec(torso, -1.0, 0.0, 0.0)
        pu = p0 * u0 + p1 * u1 + p2 * u2
        p0, p1, p2 = p0 - pu * u0, p1 - pu * u1, p2 - pu * u2
    pn = norm3(p0, p1, p2)
    p0, p1, p2 = p0 / pn, p1 / pn, p2 / pn
    a = (l1 * l1 - l2 * l2 + dist_c * dist_c) / (2.0 * dist_c)
    h = math.sqrt(max(l1 * l1 - a * a, 0.0))
    el0, el1, el2 = (s0 + a * u0) + h * p0, (s1 + a * u1) + h * p1, (s2 + a * u2) + h * p2
    c0, c1, c2 = s0 + dist_c * u0, s1 + dist_c * u1, s2 + dist_c * u2
    b0, b1, b2 = mat_vec(torso, io[ELBOW], io[ELBOW + 1], io[ELBOW + 2])
    upper = mat_mat(swing_mat(b0, b1, b2, el0 - s0, el1 - s1, el2 - s2), torso)
    b0, b1, b2 = mat_vec(upper, r0, r1, r2)
    fore = mat_mat(swing_mat(b0, b1, b2, c0 - el0, c1 - el1, c2 - el2), upper)
    if not level:
        return upper, fore, fore
    b0, b1, b2 = mat_vec(fore, io[GRIP], io[GRIP + 1], io[GRIP + 2])
    return upper, fore, mat_mat(swing_mat(b0, b1, b2, h0, h1, h2), fore)


@kernel
def lean_kernel(io: np.ndarray, out: np.ndarray, g0: float, g1: float, g2: float) -> None:
    """Turn and lean the upper body of the pose ``out`` toward a hand target ``g`` beyond the
    straight arm's reach (the rule of :meth:`handover_env.person.pose.MotionPose.lean_toward`)."""
    t = int(io[TORSO])
    b0, b1, b2 = out[t, 0], out[t, 1], out[t, 2]
    rot = quat_mat(out[t, 3], out[t, 4], out[t, 5], out[t, 6])
    s0, s1, s2 = mat_vec(rot, io[SHOULDER], io[SHOULDER + 1], io[SHOULDER + 2])
    need = norm3(b0 + s0 - g0, b1 + s1 - g1, b2 + s2 - g2) - io[STRAIGHT_REACH]
    if need <= 0.0:
        return
    h0, h1, h2 = g0 - b0, g1 - b1, g2 - b2
    x0, x1, x2 = s1 * h2 - s2 * h1, s2 * h0 - s0 * h2, s0 * h1 - s1 * h0
    n = norm3(x0, x1, x2)
    if n < 1e-9:
        return
    half = 0.5 * min(need / norm3(s0, s1, s2), io[MAX_TURN])
    sh = math.sin(half)
    w, x, y, z = math.cos(half), x0 / n * sh, x1 / n * sh, x2 / n * sh
    turn = quat_mat(w, x, y, z)
    for i in range(int(io[SEGS])):
        if io[UPPER + i] == 0.0:
            continue
        w2, x2_, y2, z2 = out[i, 3], out[i, 4], out[i, 5], out[i, 6]
        out[i, 3] = w * w2 - x * x2_ - y * y2 - z * z2
        out[i, 4] = w * x2_ + x * w2 + y * z2 - z * y2
        out[i, 5] = w * y2 - x * z2 + y * w2 + z * x2_
        out[i, 6] = w * z2 + x * y2 - y * x2_ + z * w2
        r0, r1, r2 = mat_vec(turn, out[i, 0] - b0, out[i, 1] - b1, out[i, 2] - b2)
        out[i, 0], out[i, 1], out[i, 2] = b0 + r0, b1 + r1, b2 + r2


@kernel
def interp_mat(motion: np.ndarray, i: int, a: float, k: int) -> Mat3:
    """The 3x3 matrix at columns ``k:k + 9`` of ``motion``, between frames i and i + 1."""
    b = 1.0 - a
    return (motion[i, k] * b + motion[i + 1, k] * a,
            motion[i, k + 1] * b + motion[i + 1, k + 1] * a,
            motion[i, k + 2] * b + motion[i + 1, k + 2] * a,
            motion[i, k + 3] * b + motion[i + 1, k + 3] * a,
            motion[i, k + 4] * b + motion[i + 1, k + 4] * a,
            motion[i, k + 5] * b + motion[i + 1, k + 5] * a,
            motion[i, k + 6] * b + motion[i + 1, k + 6] * a,
            motion[i, k + 7] * b + motion[i + 1, k + 7] * a,
            motion[i, k + 8] * b + motion[i + 1, k + 8] * a)


@kernel
def pose_kernel(motion: np.ndarray, io: np.ndarray, out: np.ndarray) -> None:
    """The body at ``io[TAU]``: segment origins and quaternions into ``out`` (S, 7).

    With a hand target (``io[HAS_HAND]``, at ``io[HAND:HAND + 3]``) the trunk leans toward it
    and the right arm is posed to it, the hand held level and pointing away from the shoulder
    once the target is over 5 cm from it horizontally; without one the right arm swings
    (``io[SWING_ARM]``) or keeps the motion's own (a recorded arm). The arm's quaternions keep the
    sign of the motion's (sign-continuous playback).
    """
    n_frames, segs = motion.shape[0], int(io[SEGS])
    tau = io[TAU]
    f = min(max(tau, 0.0), n_frames - 1.0)  # pose.interp
    i = min(int(f), n_frames - 2)
    a = f - i
    for s in range(segs):
        for c in range(3):
            k = 3 * s + c
            out[s, c] = motion[i, k] * (1.0 - a) + motion[i + 1, k] * a
        for c in range(4):
            k = 3 * segs + 4 * s + c
            out[s, 3 + c] = motion[i, k] * (1.0 - a) + motion[i + 1, k] * a
        q0, q1, q2, q3 = out[s, 3], out[s, 4], out[s, 5], out[s, 6]
        n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        out[s, 3], out[s, 4], out[s, 5], out[s, 6] = q0 / n, q1 / n, q2 / n, q3 / n
    t = int(io[TORSO])
    if io[HAS_HAND] > 0.0:
        g0, g1, g2 = io[HAND], io[HAND + 1], io[HAND + 2]
        lean_kernel(io, out, g0, g1, g2)
        torso = quat_mat(out[t, 3], out[t, 4], out[t, 5], out[t, 6])
        r0, r1, r2 = mat_vec(torso, io[SHOULDER], io[SHOULDER + 1], io[SHOULDER + 2])
        s0, s1, s2 = out[t, 0] + r0, out[t, 1] + r1, out[t, 2] + r2
        l0, l1 = g0 - s0, g1 - s1  # a hand held out toward an object is level
        ln = math.sqrt(l0 * l0 + l1 * l1 + 0.0 * 0.0)
        level = ln > 0.05
        hd = (l0 / ln, l1 / ln, 0.0 / ln) if level else (0.0, 0.0, 0.0)
        arm = arm_kernel(io, (s0, s1, s2), torso, (g0, g1, g2), level, hd)
    elif io[SWING_ARM] > 0.0:
        torso = quat_mat(out[t, 3], out[t, 4], out[t, 5], out[t, 6])
        base = 7 * segs
        rel0 = interp_mat(motion, i, a, base)
        rel1 = interp_mat(motion, i, a, base + 9)
        rel2 = interp_mat(motion, i, a, base + 18)
        arm = (mat_mat(torso, rel0), mat_mat(torso, rel1), mat_mat(torso, rel2))
        r0, r1, r2 = mat_vec(torso, io[SHOULDER], io[SHOULDER + 1], io[SHOULDER + 2])
        s0, s1, s2 = out[t, 0] + r0, out[t, 1] + r1, out[t, 2] + r2
    else:
        return
    for j in range(3):
        seg = int(io[ARM + j])
        w, x, y, z = mat_quat(arm[j])
        dot = w * out[seg, 3] + x * out[seg, 4] + y * out[seg, 5] + z * out[seg, 6]
        sign = -1.0 if dot < 0 else 1.0
        out[seg, 3], out[seg, 4], out[seg, 5], out[seg, 6] = w * sign, x * sign, y * sign, z * sign
    e0, e1, e2 = mat_vec(arm[0], io[ELBOW], io[ELBOW + 1], io[ELBOW + 2])
    e0, e1, e2 = s0 + e0, s1 + e1, s2 + e2
    w0, w1, w2 = mat_vec(arm[1], io[WRIST], io[WRIST + 1], io[WRIST + 2])
    w0, w1, w2 = e0 + w0, e1 + w1, e2 + w2
    u, f_, h = int(io[ARM]), int(io[ARM + 1]), int(io[ARM + 2])
    out[u, 0], out[u, 1], out[u, 2] = s0, s1, s2
    out[f_, 0], out[f_, 1], out[f_, 2] = e0, e1, e2
    out[h, 0], out[h, 1], out[h, 2] = w0, w1, w2


def motion_rows(origin: np.ndarray, quat: np.ndarray, arm_swing: np.ndarray,
                heading: np.ndarray) -> np.ndarray:
    """One row per frame for :func:`pose_kernel`: the segment origins (S x 3), quaternions
    (S x 4), the right arm's swing rotations relative to the torso (3 x 3 x 3) and the walking
    direction (yaw, rad): 7 S + 28 columns."""
    n = origin.shape[0]
    return np.ascontiguousarray(np.concatenate(
        [origin.reshape(n, -1), quat.reshape(n, -1), arm_swing.reshape(n, -1),
         np.asarray(heading, dtype=np.float64).reshape(n, 1)], axis=1), dtype=np.float64)


def arm_constants(shoulder: np.ndarray, elbow: np.ndarray, wrist: np.ndarray, grip: np.ndarray,
                  straight_reach: float = 0.0, max_turn: float = 0.0, torso: int = 0,
                  right_arm: tuple[int, int, int] = (0, 0, 0), upper_body: tuple[int, ...] = (),
                  segments: int = 0,
                  pole: tuple[float, float, float] = ELBOW_POLE_RECORDED) -> np.ndarray:
    """A person's io array for :func:`pose_kernel` and :func:`arm_kernel`: the right shoulder in
    the torso frame, the elbow in the upper arm's, the wrist in the forearm's and the grip point
    in the hand's (m), the straight arm's reach for the lean and its largest turn (rad), and the
    segment indices (torso, right arm, the upper body that turns with the torso) and the elbow's
    pole in the torso frame (:data:`ELBOW_POLE_RECORDED` or :data:`ELBOW_POLE_OUT`)."""
    io = np.zeros(IO_BASE + segments)
    io[SHOULDER:SHOULDER + 3], io[ELBOW:ELBOW + 3] = shoulder, elbow
    io[WRIST:WRIST + 3], io[GRIP:GRIP + 3] = wrist, grip
    lower = np.asarray(grip, dtype=np.float64) + wrist  # elbow -> grip with a straight wrist
    io[REST_LOWER:REST_LOWER + 3] = lower
    io[STRAIGHT_REACH], io[MAX_TURN] = straight_reach, max_turn
    io[GRIP_LEN], io[L_UPPER] = norm3(*grip.tolist()), norm3(*elbow.tolist())
    io[L_FORE], io[L_LOWER] = norm3(*wrist.tolist()), norm3(*lower.tolist())
    io[SEGS], io[TORSO], io[ARM:ARM + 3] = segments, torso, right_arm
    io[POLE:POLE + 3] = pole
    io[[UPPER + i for i in upper_body]] = 1.0
    return io

