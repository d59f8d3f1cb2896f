"""Where the simulated person's body would be if nothing interfered: the nominal motion.

A :class:`PersonMotion` is the receiver's whole-body motion at 30 Hz before any interaction:
every segment's pose (:class:`handover_env.person.skeleton.BodyPose`), the pelvis track a camera
sees, the walking direction and the right arm's walking swing. :mod:`handover_env.person.receiver`
plays it
back (possibly slower, when the person waits for the object) and replaces the right arm when
the person reaches.

Sources:

* :func:`scripted_motion`: a walker from :func:`handover_env.person.motion.sample_walker`
  (ID, or OOD wandering / pausing), its pelvis track from ``base_trajectory`` and the rest of the
  body from :func:`handover_env.person.gait.walking_pose`;
* :func:`recorded_motion`: a public recording. With the receiver's BODY_34 skeleton
  (:class:`handover_env.person.recording.Recording`, or a dict with ``receiver_pose``), the body
  is the recorded person, filtered once (:func:`handover_env.data.filtering.smooth_track`) and
  retargeted onto the rigid segments (:func:`handover_env.person.skeleton.retarget`). With the
  pelvis track only (an :class:`~handover_env.data.dataset.Episode`, e.g. synthetic data), the
  scripted gait walks along the filtered track. The camera always sees the *raw* recorded pelvis
  track.
* :func:`stopped`: the static handover's variant of any motion: it follows the motion until the
  pelvis reaches the stop line, decelerates to rest there and stands.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from handover_env.data.dataset import Episode
from handover_env.data.filtering import smooth_track
from handover_env.data.limits import MAX_ID_CHARS
from handover_env.person import motion as rm
from handover_env.person import trajectory
from handover_env.person.gait import walking_pose
from handover_env.person.recording import Recording, position_array, skeleton_array
from handover_env.person.rotations import mat_to_quat
from handover_env.person.skeleton import (
    RIGHT_ARM,
    SEG,
    BodyDims,
    BodyPose,
    measure_dims,
    retarget,
)

RATE = 30.0
DEPART_SPEED = 0.25  # m/s: the person "leaves the start point" when the pelvis first moves faster
STAND_TIME = 30.0  # s of standing appended to a stopped motion


@dataclass
class PersonMotion:
    """A receiver's nominal whole-body motion at 30 Hz (T frames).

    Attributes:
        dims: the body's rest geometry.
        origin: (T, S, 3) segment origins, m.
        quat: (T, S, 4) segment orientations (w, x, y, z), sign-continuous over time.
        camera_xy: (T, 2) pelvis xy as the camera sees it (raw for recordings).
        heading: (T,) walking direction (yaw, rad; pi = toward -x), defined when standing.
        arm_swing: (T, 3, 3, 3) the right upper arm, forearm and hand rotations relative to the
            torso while walking (used when the person's arm is modelled, not replayed).
        speed: (T,) walking speed of the (filtered) pelvis, m/s (central difference averaged
            over 0.3 s).
        kind: "id", "ood" or "replay".
        source_id: where the motion came from.
        walker: the scripted walker's parameters (None for recordings).
        has_skeleton: True when the body is a recorded skeleton (else the scripted gait).
        rest_frame: for a stopped motion (:func:`stopped`), the frame from which the person
            stands still; None for a walk.
    """

    dims: BodyDims
    origin: np.ndarray
    quat: np.ndarray
    camera_xy: np.ndarray
    heading: np.ndarray
    arm_swing: np.ndarray
    speed: np.ndarray
    kind: str
    source_id: str
    walker: rm.WalkerParams | None = None
    has_skeleton: bool = False
    rest_frame: float | None = None

    def __post_init__(self) -> None:
        n = self.origin.shape[0]
        if n < 2:
            raise ValueError("a motion needs at least 2 frames")
        for name in ("quat", "camera_xy", "heading", "arm_swing", "speed"):
            if getattr(self, name).shape[0] != n:
                raise ValueError(
                    f"PersonMotion.{name} has {getattr(self, name).shape[0]} frames, expected {n}"
                )

    @property
    def frames(self) -> int:
        return int(self.origin.shape[0])

    @property
    def duration(self) -> float:
        """Length, s."""
        return (self.frames - 1) / RATE

    @property
    def t_depart(self) -> float:
        """When the pelvis first moves faster than ``DEPART_SPEED`` (5-frame mean), s; the start
        of the paper's handover time (Sec. V-C)."""
        speed = np.linalg.norm(np.gradient(self.camera_xy, axis=0), axis=1) * RATE
        if speed.size >= 5:
            speed = np.convolve(np.pad(speed, 2, mode="edge"), np.ones(5) / 5.0, "valid")
        moving = np.nonzero(speed > DEPART_SPEED)[0]
        return (int(moving[0]) if moving.size else self.frames - 1) / RATE


def _sign_continuous(q: np.ndarray) -> np.ndarray:
    """Flip quaternions along axis 0 so that consecutive ones have a positive dot product."""
    q = q.copy()
    for k in range(1, q.shape[0]):
        flip = np.sum(q[k] * q[k - 1], axis=-1) < 0
        q[k][flip] *= -1.0
    return q


def _heading(xy: np.ndarray) -> np.ndarray:
    """Walking direction of a (filtered) pelvis track; held while standing, -x before moving."""
    vel = np.gradient(xy, axis=0) * RATE
    heading = np.empty(len(xy))
    last = math.pi
    moving = np.linalg.norm(vel, axis=1) > 0.15
    if moving.any():
        first = int(np.argmax(moving))
        last = math.atan2(vel[first, 1], vel[first, 0])
    for k in range(len(xy)):
        if moving[k]:
            last = math.atan2(vel[k, 1], vel[k, 0])
        heading[k] = last
    return np.unwrap(heading)


def _gait_track(xy: np.ndarray, heading: np.ndarray, height: float) -> trajectory.BaseTrajectory:
    """A BaseTrajectory along a given pelvis track, stride phase from the distance walked."""
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    dist = np.concatenate([[0.0], np.cumsum(step)])
    phase = 2 * math.pi * dist / (2 * 0.28 * height)
    t = np.arange(len(xy)) / RATE
    return trajectory.BaseTrajectory(
        t=t, xy=xy, heading=heading, gait_phase=np.mod(phase, 2 * math.pi)
    )


def _arm_swing(pose: BodyPose) -> np.ndarray:
    """(T, 3, 3, 3) right-arm rotations relative to the torso."""
    torso = pose.rot[:, SEG["torso"]]
    return np.stack([np.swapaxes(torso, -1, -2) @ pose.rot[:, i] for i in RIGHT_ARM], axis=1)


def _speed(xy: np.ndarray) -> np.ndarray:
    """Walking speed of a pelvis track (central difference, 9-frame moving average), m/s."""
    v = np.linalg.norm(np.gradient(xy, axis=0), axis=1) * RATE
    return np.convolve(np.pad(v, 4, mode="edge"), np.ones(9) / 9.0, "valid")


def _from_pose(pose: BodyPose, dims: BodyDims, camera_xy: np.ndarray, heading: np.ndarray,
               arm_swing: np.ndarray, **kw: Any) -> PersonMotion:
    return PersonMotion(dims=dims, origin=pose.origin, quat=_sign_continuous(mat_to_quat(pose.rot)),
                        camera_xy=np.asarray(camera_xy, dtype=np.float64), heading=heading,
                        arm_swing=arm_swing, speed=_speed(pose.origin[:, 0, :2]), **kw)


def scripted_motion(rng: np.random.Generator, kind: str = "id", height: float | None = None,
                    speed: float | None = None, overrides: dict | None = None) -> PersonMotion:
    """A scripted ID/OOD walker drawn from ``rng`` (see
    :func:`handover_env.person.motion.sample_walker`)."""
    fixed = rm.check_overrides(overrides) if overrides is not None else {}
    if height is not None:
        fixed["height"] = float(height)
    if speed is not None:
        fixed["speed"] = float(speed)
    walker = rm.sample_walker(rng, kind, **fixed)
    traj = trajectory.base_trajectory(walker, rate_hz=RATE)
    dims = BodyDims.from_height(walker.height)
    pose = walking_pose(traj, dims)
    heading = np.unwrap(np.asarray(traj.heading, dtype=np.float64))
    return _from_pose(pose, dims, traj.xy, heading, _arm_swing(pose), kind=kind,
                      source_id=f"scripted_{kind}", walker=walker)


def replay_input(source: Any) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The checked ``(receiver_xy (T, 2), receiver_pose (T, 34, 3) or None, source_id)`` of a
    replay, one check for every form (:func:`recorded_motion`'s ``source``).

    Tracks and skeletons go through :func:`handover_env.person.recording.position_array`: real
    numbers only, finite, within the +-MAX_ABS_COORD_M an :class:`Episode` may hold; a skeleton
    also needs every bone (:func:`handover_env.person.skeleton.shortest_bone`) at least MIN_BONE_M
    long.

    Raises:
        ValueError (:class:`~handover_env.data.dataset.DatasetError`): naming the field.
    """
    if isinstance(source, Recording):
        xy, pose, source_id = source.episode.receiver_xy, source.receiver_pose, source.source_id
    elif isinstance(source, Episode):
        xy, pose, source_id = source.receiver_xy, None, source.source_id
    elif isinstance(source, Mapping):
        xy, pose = source.get("receiver_xy"), source.get("receiver_pose")
        source_id = source.get("source_id")
        source_id = "replay" if source_id is None else source_id
        if xy is None:
            raise ValueError("a replayed receiver needs 'receiver_xy' (T, 2)")
        if not isinstance(source_id, str) or not 0 < len(source_id) <= MAX_ID_CHARS:
            raise ValueError(
                f"replay source_id must be a string of 1 to {MAX_ID_CHARS} characters, got "
                f"{source_id!r:.80}"
            )
    else:
        raise ValueError(
            "a replayed receiver is a Recording, an Episode or a dict with 'receiver_xy', got "
            f"{type(source).__name__}"
        )
    xy = position_array(xy, "replay receiver_xy", (2,))
    if pose is not None:
        pose = skeleton_array(pose, xy.shape[0], "replay receiver_pose")
    return xy, pose, source_id


def recorded_motion(source: Any, height: float | None = None) -> PersonMotion:
    """The nominal motion of a recorded receiver.

    Args:
        source: a :class:`~handover_env.person.recording.Recording` (skeleton and episode), an
            :class:`~handover_env.data.dataset.Episode`, or a dict with ``receiver_xy`` (T, 2) and
            optionally ``receiver_pose`` (T, 34, 3) and ``source_id``; 30 Hz.
        height: body height, m (default: measured from the skeleton, else 1.725).

    Raises:
        ValueError: a malformed replay (:func:`replay_input`), or a skeleton whose body height
            is not a person's (:data:`handover_env.person.motion.HEIGHT_RANGE`).
    """
    raw_xy, skeleton, source_id = replay_input(source)
    if skeleton is not None:
        joints = smooth_track(skeleton, RATE)
        dims = measure_dims(joints, height)
        lo, hi = rm.HEIGHT_RANGE
        if not lo <= dims.height <= hi:
            raise ValueError(
                f"replay receiver_pose: the body height "
                f"{'given' if height is not None else 'measured from the HEAD joint'} is "
                f"{dims.height:.3g} m, outside [{lo:g}, {hi:g}] m (the skeleton must be a person "
                "standing in the dataset's frame: z up, floor at z = 0)"
            )
        pose = retarget(joints, dims)
        xy = joints[:, 0, :2]
        heading = _heading(xy)
        gait = walking_pose(_gait_track(xy, heading, dims.height), dims)
        return _from_pose(pose, dims, raw_xy, heading, _arm_swing(gait), kind="replay",
                          source_id=source_id, has_skeleton=True)
    dims = BodyDims.from_height(float(height) if height is not None else 1.725)
    xy = smooth_track(raw_xy, RATE)
    heading = _heading(xy)
    pose = walking_pose(_gait_track(xy, heading, dims.height), dims)
    return _from_pose(
        pose, dims, raw_xy, heading, _arm_swing(pose), kind="replay", source_id=source_id
    )


def resample(motion: PersonMotion, tau: np.ndarray) -> PersonMotion:
    """The motion played at fractional frame indices ``tau`` (one output frame per entry)."""
    tau = np.clip(np.asarray(tau, dtype=np.float64), 0.0, motion.frames - 1.0)
    i = np.minimum(np.floor(tau).astype(np.int64), motion.frames - 2)
    a = tau - i

    def lerp(x: np.ndarray) -> np.ndarray:
        w = a.reshape((-1,) + (1,) * (x.ndim - 1))
        return x[i] * (1.0 - w) + x[i + 1] * w

    quat = lerp(motion.quat)
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    swing = lerp(motion.arm_swing)
    u, _, vt = np.linalg.svd(swing)  # re-orthonormalise the interpolated rotations
    dtau = np.gradient(tau) if tau.size > 1 else np.zeros_like(tau)
    return replace(motion, origin=lerp(motion.origin), quat=quat, camera_xy=lerp(motion.camera_xy),
                   heading=lerp(motion.heading), arm_swing=u @ vt, speed=lerp(motion.speed) * dtau)


def stopped(motion: PersonMotion, stop_x: float, decel_time: float = 0.8) -> PersonMotion:
    """The static-handover variant: follow ``motion`` until the pelvis reaches ``x <= stop_x``,
    decelerate smoothly (half-cosine speed ramp of ``decel_time`` s) to rest there and stand.

    The ramp starts ``decel_time / 2`` s of walking before the stop line, so the person comes to
    rest about on it. A motion that never reaches the line stops at its end.
    """
    xy = motion.camera_xy if not motion.has_skeleton else motion.origin[:, 0, :2]
    reach = np.nonzero(xy[:, 0] <= stop_x)[0]
    k_stop = int(reach[0]) if reach.size else motion.frames - 1
    ramp = decel_time * RATE
    k0 = max(k_stop - 0.5 * ramp, 0.0)
    n_out = math.ceil(k0 + ramp + STAND_TIME * RATE) + 1
    t = np.arange(n_out, dtype=np.float64)
    # Playback speed 1 until k0, then 0.5 (1 + cos(pi s)) down to 0 over the ramp: tau advances
    # by ramp / 2 frames during it, so it comes to rest at k0 + ramp / 2 = k_stop.
    s = np.clip((t - k0) / ramp, 0.0, 1.0)
    tau = np.where(t <= k0, t, k0 + ramp * (s + np.sin(math.pi * s) / math.pi) / 2.0)
    return replace(resample(motion, np.minimum(tau, motion.frames - 1.0)), rest_frame=k0 + ramp)
