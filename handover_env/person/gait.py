"""Full-body motion of the scripted walker, and the arm posture for a hand target.

The scripted receiver's pelvis track (position, heading, stride phase) comes from
:func:`handover_env.person.trajectory.base_trajectory`, the model shared with the synthetic dataset.
This module adds the rest of the body as :class:`handover_env.person.skeleton.BodyPose` rotations
on top of the rest pose, so that scripted and recorded receivers drive the body the same way:

* **legs**: hip flexion ``HIP_AMPLITUDE`` sin(phase) and a knee that flexes during the swing
  (peak ``KNEE_PEAK``), the left leg half a stride behind the right;
* **arms**: shoulder flexion opposite to the leg on the same side (``ARM_AMPLITUDE``) with a
  slightly bent elbow; the right arm's swing amplitude matches the hand's forward swing in
  :func:`~handover_env.person.trajectory.hand_position` (``HAND_SWING_RATIO`` of the height);
* **trunk**: upright, with a small forward lean and vertical bob twice per stride.

Joint angles are typical adult walking kinematics at 0.8-1.2 m/s (Winter, *Biomechanics and Motor
Control of Human Movement*, 2009: hip flexion/extension about +-20-25 deg, knee flexion up to
about 60 deg in swing, arm swing about +-15-20 deg at the shoulder).

:func:`arm_pose` is the right arm's two-link inverse kinematics (shoulder ball, elbow) for a grip
point target, with the elbow down and slightly out, as a person holding an object out does.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.person.posing import arm_constants, arm_kernel
from handover_env.person.rotations import yaw_matrix
from handover_env.person.skeleton import (
    SEG,
    SEGMENTS,
    BodyDims,
    BodyPose,
    J,
    forward_kinematics,
)
from handover_env.person.trajectory import BaseTrajectory

HIP_AMPLITUDE = math.radians(22.0)
KNEE_PEAK = math.radians(60.0)
ARM_AMPLITUDE = math.radians(16.0)
ELBOW_BEND = math.radians(15.0)
TRUNK_LEAN = math.radians(4.0)
BOB_AMPLITUDE = 0.015  # m, pelvis vertical bob (twice per stride)


def _rot_y(angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation about the body's lateral (y, left) axis; positive tips z toward x."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(angle) + (3, 3))
    out[..., 0, 0], out[..., 0, 2], out[..., 1, 1], out[..., 2, 0], out[..., 2, 2] = (
        c,
        s,
        1.0,
        -s,
        c,
    )
    return out


def walking_pose(traj: BaseTrajectory, dims: BodyDims) -> BodyPose:
    """The scripted walker's whole body at every frame of ``traj``: BodyPose of shape (T, S, ...).

    A limb swung *forward* by angle a is its rest pose turned by -a about the lateral axis.
    """
    phase = np.asarray(traj.gait_phase, dtype=np.float64)
    n = phase.shape[0]
    speed = np.linalg.norm(np.gradient(traj.xy, axis=0), axis=1) / max(
        float(np.median(np.diff(traj.t))), 1e-9
    )
    moving = np.clip(speed / 0.5, 0.0, 1.0)  # no swing while standing (paused walkers)
    base = yaw_matrix(traj.heading)  # body x forward along the walking direction
    rot = np.empty((n, len(SEGMENTS), 3, 3))
    rot[:, SEG["pelvis"]] = base
    trunk = base @ _rot_y(np.full(n, TRUNK_LEAN))
    rot[:, SEG["torso"]] = trunk
    rot[:, SEG["head"]] = trunk @ _rot_y(np.full(n, -TRUNK_LEAN))
    for side, offset in (("r", 0.0), ("l", math.pi)):
        p = phase + offset
        hip = -HIP_AMPLITUDE * np.sin(p) * moving  # right thigh forward when sin(p) > 0
        # Knee: flexes in the swing (thigh moving forward: cos(p) > 0), straight in the stance.
        knee = KNEE_PEAK * np.clip(np.cos(p - 0.6), 0.0, 1.0) ** 2 * moving
        thigh = base @ _rot_y(hip)
        rot[:, SEG["thigh_" + side]] = thigh
        rot[:, SEG["shank_" + side]] = thigh @ _rot_y(knee)
        # The arm swings opposite to the leg of the same side.
        arm = ARM_AMPLITUDE * np.sin(p) * moving
        upper = trunk @ _rot_y(arm)
        rot[:, SEG["upper_arm_" + side]] = upper
        fore = upper @ _rot_y(np.full(n, -ELBOW_BEND))
        rot[:, SEG["forearm_" + side]] = fore
        rot[:, SEG["hand_" + side]] = fore
    pelvis = np.concatenate(
        [traj.xy, (dims.pelvis_z + BOB_AMPLITUDE * (np.cos(2.0 * phase) * moving - 1.0))[:, None]],
        axis=1,
    )
    return BodyPose(origin=forward_kinematics(pelvis, rot, dims), rot=rot)


def arm_pose(shoulder: np.ndarray, torso_rot: np.ndarray, grip: np.ndarray, dims: BodyDims,
             hand_dir: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotations of the right upper arm, forearm and hand that put the grip point at ``grip``.

    Two-link inverse kinematics (shoulder ball, elbow) for the wrist, whose position follows from
    the grip point and the hand's direction: with ``hand_dir`` the hand points that way from the
    wrist to the grip point (a hand held out level toward an object, the wrist bent as needed);
    without it the hand stays in line with the forearm (wrist straight) and the second link runs
    to the grip point. A target beyond reach is approached along the line from the shoulder. The
    elbow lies in the plane of the shoulder-wrist line and a pole in the torso frame
    (:data:`handover_env.person.posing.ELBOW_POLE_RECORDED`: down and back, as the recorded
    receivers held their elbow at the transfer).

    Args:
        shoulder: (3,) right shoulder (upper arm origin), world.
        torso_rot: (3, 3) torso rotation (parent of the upper arm).
        grip: (3,) target of the grip point, world.
        dims: the body's rest geometry.
        hand_dir: (3,) unit direction from the wrist to the grip point, or None.

    Returns:
        (upper arm, forearm, hand) world rotations, each (3, 3).
    """
    ua, fa = SEG["upper_arm_r"], SEG["forearm_r"]
    io = arm_constants(dims.local(J["RIGHT_SHOULDER"], SEG["torso"]),
                       dims.local(J["RIGHT_ELBOW"], ua), dims.local(J["RIGHT_WRIST"], fa),
                       dims.grip("r"))
    level = hand_dir is not None
    hd = (0.0, 0.0, 0.0) if hand_dir is None else tuple(
        np.asarray(hand_dir, dtype=np.float64).tolist())
    rots = arm_kernel(io, tuple(np.asarray(shoulder, dtype=np.float64).tolist()),
                      tuple(np.asarray(torso_rot, dtype=np.float64).ravel().tolist()),
                      tuple(np.asarray(grip, dtype=np.float64).tolist()), level, hd)
    upper, fore, hand = (np.array(r).reshape(3, 3) for r in rots)
    return upper, fore, hand
