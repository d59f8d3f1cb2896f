"""The simulated person's body at a playback position of their nominal motion.

A :class:`MotionPose` reads a :class:`handover_env.person.person.PersonMotion` at a fractional
frame ``tau``: the pelvis, the right shoulder and the walking direction, the grip point of the
walking arm swing or of the recorded arm, and the whole body's segment poses with the right arm
posed toward a hand target (two-link inverse kinematics, :func:`handover_env.person.gait.arm_pose`)
and the trunk turned and leaned toward a far one. Velocities scale with the playback speed
factor ``rho`` (1 = as recorded). :class:`handover_env.person.receiver.Receiver` decides the hand
target; this module only poses the body.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.person.person import RATE, PersonMotion
from handover_env.person.posing import (
    ELBOW_POLE_RECORDED,
    HAND,
    HAS_HAND,
    SWING_ARM,
    TAU,
    arm_constants,
    motion_rows,
    pose_kernel,
)
from handover_env.person.rotations import length
from handover_env.person.skeleton import RIGHT_ARM, SEG, SEGMENTS, J

#: The arm counts as straight at this fraction of its full length (the elbow never locks).
STRAIGHT_ARM = 0.97
#: The farthest the trunk turns and leans toward a far hand target, rad (20 deg).
TRUNK_MAX_TURN = math.radians(20.0)
#: The torso and the segments it carries (head, both arms), which turn with it.
UPPER_BODY = tuple(i for i in range(len(SEGMENTS)) if i == SEG["torso"] or SEGMENTS[i].parent in (
    SEG["torso"], SEG["upper_arm_r"], SEG["forearm_r"], SEG["upper_arm_l"], SEG["forearm_l"]))
#: Multiplies a unit quaternion (w, x, y, z) into its conjugate, the inverse rotation.
QUAT_CONJ = np.array([1.0, -1.0, -1.0, -1.0])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) quaternions."""
    w1, x1, y1, z1 = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    w2, x2, y2, z2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[..., 1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[..., 2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[..., 3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    return out


def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """The rotation matrix (3, 3) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def frame_weight(n: int, tau: float) -> tuple[int, float]:
    """``(i, a)``: the fractional frame ``tau`` of ``n`` frames (clamped) lies ``a`` of the way
    from frame ``i`` to frame ``i + 1``."""
    f = min(max(tau, 0.0), n - 1.0)
    i = min(int(f), n - 2)
    return i, f - i


def interp(frames: np.ndarray, tau: float) -> np.ndarray:
    """``frames`` (T, ...) linearly interpolated at the fractional frame ``tau`` (clamped)."""
    i, a = frame_weight(frames.shape[0], tau)
    return frames[i] * (1.0 - a) + frames[i + 1] * a


class MotionPose:
    """The body of one person's nominal motion at playback positions.

    Args:
        motion: the person's nominal motion (its ``dims`` fix the body's proportions).

    Attributes:
        shoulder_local: the right shoulder in the torso frame, m.
        grip_local: the right hand's grip point in the hand frame, m.
        arm_reach: shoulder to grip point of the straight right arm, m.
        rows: the motion, one row per frame, as the compiled pose reads it
            (:func:`handover_env.person.posing.motion_rows`).
        io: the body's constants and a pose call's inputs
            (:func:`handover_env.person.posing.arm_constants`).
    """

    def __init__(self, motion: PersonMotion,
                 elbow_pole: tuple[float, float, float] = ELBOW_POLE_RECORDED) -> None:
        self.motion = motion
        dims = motion.dims
        self.shoulder_local = dims.local(J["RIGHT_SHOULDER"], SEG["torso"])
        self.grip_local = dims.grip("r")
        self._elbow_local = dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"])
        self._wrist_local = dims.local(J["RIGHT_WRIST"], SEG["forearm_r"])
        self.arm_reach = float(
            np.linalg.norm(dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"]))
            + np.linalg.norm(dims.grip("r") + dims.local(J["RIGHT_WRIST"], SEG["forearm_r"]))
        )
        self.rows = motion_rows(motion.origin, motion.quat, motion.arm_swing, motion.heading)
        self.io = arm_constants(self.shoulder_local, self._elbow_local, self._wrist_local,
                                 self.grip_local, STRAIGHT_ARM * self.arm_reach, TRUNK_MAX_TURN,
                                 SEG["torso"], RIGHT_ARM, UPPER_BODY, len(SEGMENTS), elbow_pole)

    def body_frame(self, tau: float, rho: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(right shoulder, walking direction (3,), walking speed) at playback position tau."""
        m = self.motion
        torso_q = interp(m.quat[:, SEG["torso"]], tau)
        torso = quat_to_mat(torso_q / length(torso_q))
        shoulder = interp(m.origin[:, SEG["torso"]], tau) + torso @ self.shoulder_local
        h = float(interp(m.heading, tau))
        u = np.array([math.cos(h), math.sin(h), 0.0])
        return shoulder, u, float(interp(m.speed, tau)) * rho

    def shoulder_track(self) -> tuple[np.ndarray, np.ndarray]:
        """The right shoulder (T, 3) and the horizontal walking direction (T, 3) at every frame of
        the nominal motion (as :meth:`body_frame` at integer frames, vectorised)."""
        m = self.motion
        q = m.quat[:, SEG["torso"]]
        w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
        rot = np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ], axis=1)
        rot_s = rot @ self.shoulder_local
        h = np.asarray(m.heading, dtype=np.float64)
        forward = np.stack([np.cos(h), np.sin(h), np.zeros_like(h)], axis=1)
        return m.origin[:, SEG["torso"]] + rot_s, forward

    def pelvis(self, tau: float, rho: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nominal pelvis position, rotation and velocity at tau."""
        m = self.motion
        q = interp(m.quat[:, 0], tau)
        i = min(int(tau), m.frames - 2)
        vel = (m.origin[i + 1, 0] - m.origin[i, 0]) * RATE * rho
        return interp(m.origin[:, 0], tau), quat_to_mat(q / length(q)), vel

    def swing_hand(self, tau: float, rho: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grip point of the walking swing at tau, with its velocity (zero acceleration)."""
        p0 = self.grip_from_arm(tau, self.motion.arm_swing)
        p1 = self.grip_from_arm(tau + 1.0, self.motion.arm_swing)
        return p0, (p1 - p0) * RATE * rho, np.zeros(3)

    def arm_rotations(self, tau: float, arm: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """The torso's rotation and the right arm's segment rotations (world frame) at tau, for
        arm rotations ``arm`` (T, 3, 3, 3) relative to the torso."""
        m = self.motion
        torso_q = interp(m.quat[:, SEG["torso"]], tau)
        torso = quat_to_mat(torso_q / length(torso_q))
        rel = interp(arm, tau)
        return torso, [torso @ rel[k] for k in range(3)]

    def grip_from_arm(self, tau: float, arm: np.ndarray) -> np.ndarray:
        """Grip point of the right hand at tau for arm rotations ``arm`` relative to the torso."""
        torso, rots = self.arm_rotations(tau, arm)
        m, dims = self.motion, self.motion.dims
        shoulder = interp(m.origin[:, SEG["torso"]], tau) + torso @ self.shoulder_local
        elbow = shoulder + rots[0] @ dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"])
        wrist = elbow + rots[1] @ dims.local(J["RIGHT_WRIST"], SEG["forearm_r"])
        return wrist + rots[2] @ self.grip_local

    def recorded_grip(self, tau: float) -> np.ndarray:
        """Grip point of the recorded right arm at tau."""
        m = self.motion
        q = interp(m.quat[:, SEG["hand_r"]], tau)
        rot = quat_to_mat(q / length(q))
        return interp(m.origin[:, SEG["hand_r"]], tau) + rot @ self.grip_local

    def at(
        self, tau: float, hand: np.ndarray | None, swing_arm: bool,
        out: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Segment origins (S, 3) and quaternions (S, 4) at playback position tau
        (:func:`handover_env.person.posing.pose_kernel`).

        With a hand target the upper body turns and leans toward it when it lies beyond the
        straight arm's reach: people reaching far bring their shoulder toward the target, so the
        torso (with the head and arms) rotates about its base toward the target by the smallest
        rotation that brings the shoulder close enough, at most ``TRUNK_MAX_TURN``. The right arm
        is then posed to the target (:func:`handover_env.person.gait.arm_pose`'s rule), the hand
        held level, pointing away from the shoulder.

        Args:
            tau: playback position, frames.
            hand: the right hand's grip target (the arm is posed to it and the trunk leans
                toward it), or None.
            swing_arm: without a hand target, pose the right arm in its walking swing (the
                modelled hand) instead of leaving the motion's own arm (a recorded hand).
            out: (S, 7) array to write the pose into (origins, then quaternions); a new one if
                None. The returned arrays are views of it.
        """
        io = self.io
        io[TAU] = tau
        if hand is None:
            io[HAS_HAND] = 0.0
        else:
            io[HAS_HAND] = 1.0
            io[HAND:HAND + 3] = hand
        io[SWING_ARM] = 1.0 if swing_arm else 0.0
        if out is None:
            out = np.empty((len(SEGMENTS), 7))
        pose_kernel(self.rows, io, out)
        return out[:, :3], out[:, 3:]
