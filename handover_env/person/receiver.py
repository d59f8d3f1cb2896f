"""The simulated person: walks, reaches, grasps and pulls, and moves the body's targets in MuJoCo.

The body (:mod:`handover_env.person.body_model`) follows per-segment targets through soft welds.
This module decides where those targets are, at the env's 30 Hz and, interpolated, at every 200 Hz
controller tick:

* **Walking.** The nominal motion (:class:`handover_env.person.person.PersonMotion`: a recorded
  person or the scripted walker) is played back at a speed factor rho (1 = as recorded). A person
  waiting for an object they cannot reach yet slows down (rho falls at ``slow_rate`` per second, not
  below ``min_speed_factor``) and speeds up again once it is within reach; the camera sees the
  pelvis of this played-back walk.
* **Reaching** (``hand_mode="reach"``, the modelled hand): the person reaches when the object
  will be at a comfortable place along their own path soon: its grasp point is predicted to come
  within ``comfort_reach`` of the right shoulder when it is ``meet_forward`` ahead of it, in at
  most ``reach_lead_time``. The hand then moves on a minimum-jerk path re-planned every step
  toward the moving grasp point (Hoff & Arbib 1993), with a nominal duration ``reach_duration``.
  The arm follows by two-link inverse kinematics (:func:`handover_env.person.gait.arm_pose`). If the
  object falls behind the shoulder by ``give_up_behind`` unheld, the person walks on (a miss).
* **Recorded hand** (``hand_mode="recorded"``): the right arm is the recorded one; when the
  recorded grip point comes within ``close_radius`` of the object's grasp point, the hand closes
  onto it on a minimum-jerk path of ``close_time`` (the last few cm a hand travels when it
  grasps; the ZED hand joint sits 0.04-0.16 m off the object at the recorded transfers).
* **Grasp rule**: the hand grasps when its grip point (the RIGHT_HAND joint) is within
  ``grasp_radius`` of the object's grasp point (on the bottle's axis, ``grasp_offset`` below its
  centre, below the gripper's pads): the ``receiver_grasp`` weld switches on with zero initial
  force. Then the hand draws the object toward the carry pose while the person walks on, which
  is the pull that the wrist sensor measures.
* **Static handover** (``present_after_walk``): the person stops (see
  :func:`handover_env.person.person.stopped`), raises the right hand to ``PRESENT_OFFSET`` from the
  shoulder in ``present_time`` and waits until the robot brings the object within
  ``present_reach``; then takes it.

Effort (``effort()``): the largest grip-shoulder distance while reaching or holding, the time
the arm is out (reaching, raised, or holding before the release), the time lost to slowing
down and the slowest speed factor, and how far contact pushed the pelvis off its target.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from handover_env.person import motion as rm
from handover_env.person.body_model import apply_dims, weld_lag_times
from handover_env.person.gait import arm_pose
from handover_env.person.grip import ArmGrip
from handover_env.person.min_jerk import min_jerk_step
from handover_env.person.person import RATE, PersonMotion, recorded_motion, scripted_motion, stopped
from handover_env.person.skeleton import RIGHT_ARM, SEG, SEGMENTS, J, mat_to_quat
from handover_env.robot.scene import SceneIds

CAMERA_RATE = RATE
STATES = ("walking", "reaching", "holding", "presenting", "presented", "passed")
#: Shortest re-planning horizon of a hand that holds a point fixed to the body, s.
HOLD_TRACKING = 0.3
#: The arm counts as straight at this fraction of its full length (the elbow never locks).
STRAIGHT_ARM = 0.97
#: The farthest the trunk turns and leans toward a far hand target, rad (20 deg).
TRUNK_MAX_TURN = math.radians(20.0)
#: The torso and the segments it carries (head, both arms), which turn with it.
_UPPER_BODY = tuple(i for i in range(len(SEGMENTS)) if i == SEG["torso"] or SEGMENTS[i].parent in (
    SEG["torso"], SEG["upper_arm_r"], SEG["forearm_r"], SEG["upper_arm_l"], SEG["forearm_l"]))
_CONJ = np.array([1.0, -1.0, -1.0, -1.0])
#: Speed and acceleration up to which a segment's target is led by the feed-forward, m/s and
#: m/s^2 (peak hand speeds of fast human reaches are about 2-3 m/s).
MAX_SEGMENT_SPEED = 3.0
MAX_SEGMENT_ACCEL = 30.0

#: A hand drawing an object out keeps it this far from the pelvis axis (horizontally), m: the
#: held bottle stays clear of the torso.
CARRY_CLEARANCE = 0.35
#: A held object counts as out of the (released) gripper once its centre is this far from the
#: TCP (m): the bottle's radius plus the open fingers' depth.
CLEAR_OF_GRIPPER = 0.1
#: An object behind the person counts as walked past only if it is within this distance, m.
PASS_DISTANCE = 1.2
#: Where the static receiver holds the raised right hand: forward, right and up from the
#: shoulder in the body frame, m (a hand held out in front, below shoulder height).
PRESENT_OFFSET = (0.30, -0.15, -0.15)

# Ranges of the person settings (ReceiverConfig; the envs' ``person=`` overrides). A value
# outside its range is refused with the setting and the range named.
#: The env's longest episode, s (StaticHandover-v0: 600 steps at 30 Hz): a slower movement never
#: ends within an episode.
LONGEST_EPISODE = 20.0
#: The shortest movement, s: one env step (the hand's path is re-planned once per step).
SHORTEST_MOVE = 1.0 / RATE
#: The longest arm's reach, m: shoulder to grip centre of a 2.3 m body (ARM_REACH_RATIO 0.386).
LONGEST_REACH = 0.9
#: The ``height`` reset option's range, m (adults; the walker model itself takes 1.0 .. 2.3).
HEIGHT_OPTION_RANGE = (1.2, 2.2)
#: Half the height of the bottle handed over, m (handover_env/assets/scene.xml: size 0.033 0.1).
OBJECT_HALF_HEIGHT = 0.1
#: (low, high, unit, where the range comes from) of every ReceiverConfig field.
SETTING_RANGES: dict[str, tuple[float, float, str, str]] = {
    "reach_duration": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "reach_lead_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "meet_forward": (0.0, LONGEST_REACH, "m", "ahead of the pelvis within the longest reach"),
    "comfort_fraction": (0.1, 2.0, "", "of the arm's length"),
    "min_speed_factor": (0.05, 1.0, "", "a waiting person walks at least 1/20 of their speed"),
    "slow_rate": (1.0 / LONGEST_EPISODE, RATE, "1/s",
                  "changes the speed factor by 1 over the longest episode .. in one env step"),
    "give_up_behind": (0.0, 1.0, "m", f"an object is walked past only within {PASS_DISTANCE} m"),
    "hold_time": (0.0, LONGEST_EPISODE, "s", "up to the longest episode"),
    "pull_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "pull_distance": (0.0, LONGEST_REACH, "m", "within the longest reach"),
    "grasp_radius": (0.005, 2 * OBJECT_HALF_HEIGHT, "m", "5 mm .. the bottle's height"),
    "grasp_speed": (0.01, MAX_SEGMENT_SPEED, "m/s", "up to a fast human hand"),
    "grasp_offset": (-OBJECT_HALF_HEIGHT, OBJECT_HALF_HEIGHT, "m",
                     "on the bottle's axis, within its half-height"),
    "approach_distance": (0.0, 0.5 * LONGEST_REACH, "m", "within half the longest reach"),
    "approach_height": (0.0, 0.5 * LONGEST_REACH, "m", "within half the longest reach"),
    "close_radius": (0.005, LONGEST_REACH, "m", "5 mm .. the longest reach"),
    "close_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "carry_forward": (0.0, 0.5 * LONGEST_REACH, "m", "within half the longest reach"),
    "present_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "present_reach": (0.005, LONGEST_REACH, "m", "5 mm .. the longest reach"),
}


@dataclass(frozen=True)
class ReceiverConfig:
    """How the person reaches, grasps, holds, slows down and pulls (see the module docstring).

    The defaults are calibrated on the calibration half (Table I folds 0-4) of the development
    copy's ID recordings by ``python -m handover_env.data transfer-stats``
    (``docs/calibration/receiver_calibration.md``; medians unless said otherwise):

    Args:
        reach_duration: onset to grasp of a reach, s (0.63).
        reach_lead_time: the reach starts when the object will be at the meeting point within
            this time, s (the onset leads the transfer by the reach duration, 0.63).
        meet_forward: how far ahead of the pelvis, along the walk, people take the object, m (0.35).
        comfort_fraction: the farthest people take the object from, as a fraction of their arm
            length (shoulder-elbow-wrist-hand joints): p95 of the object-shoulder distance over
            the arm length at transfer, 1.10 (median 0.86; the grip centre lies beyond the hand
            joint, and the trunk turns toward the object). People start to reach for an object
            that they can reach when they meet it (straight arm and turned trunk); if it will be
            farther than this fraction, they also slow down (down to ``min_speed_factor``).
        min_speed_factor: the slowest people walk while waiting for the object, as a fraction of
            their own speed (p25 of the minimum walking speed in the handover window relative to
            the speed before the reach, 0.82; the median, 0.91, is above the same measure in a
            window without a handover, 0.75: people do not slow down for a handover that is on
            time). ``slow_rate``: how fast the speed factor changes, 1/s.
        give_up_behind: an unheld object this far behind the shoulder (along the walk) is left
            behind: the person walks past, m.
        hold_time: after the grasp the arm stays out, moving with the body, for this long before
            drawing back, s (arm-extended time 1.30 s minus the reach, 0.67; the hand is drawn
            back 0.37 s before the giver lets go, 1.0 s after the grasp: 0.63).
        pull_time: how long drawing the hand back takes, s: first straight toward the body at
            the height of the hold, by ``pull_distance`` (m, but no closer than
            ``CARRY_CLEARANCE`` to the pelvis axis), until the object is clear of the gripper,
            then down to the carry pose.
        grasp_radius: the hand grasps when its grip point is this close to the grasp point, m,
        grasp_speed: and moves relative to it slower than this, m/s (a hand closes on an object
            it has caught up with; the grip is then :mod:`handover_env.person.grip`'s spring).
        grasp_offset: the grasp point's offset from the object's centre along its axis, m: the
            top of the bottle, above the gripper's pads (a modelled reach, which lifts the hand
            above the object), or its bottom, below the pads (a recorded hand that closes in
            from below).
        approach_distance, approach_height: the hand approaches the grasp point from this far
            toward the person and this far above it, closing in over the last ``close_time``, m.
        close_radius: recorded hand: the hand closes onto the object once the recorded grip point
            is this close to the object's centre, m (0.28: p95 of the recorded hand joint's
            distance from the object at the transfer; the ZED hand joint sits 0.17 m off the
            object there in the median recording).
        close_time: the closing motion's duration, s.
        carry_forward: the carry pose is this far forward of the hand's walking swing, m.
        present_time: static handover: time to raise the hand, s.
        present_reach: static handover: the raised hand takes the object once it is this close, m.
    """

    reach_duration: float = 0.63
    reach_lead_time: float = 0.63
    meet_forward: float = 0.35
    comfort_fraction: float = 1.10
    min_speed_factor: float = 0.82
    slow_rate: float = 1.5
    give_up_behind: float = 0.35
    hold_time: float = 0.63
    pull_time: float = 0.5
    pull_distance: float = 0.2
    grasp_radius: float = 0.03
    grasp_speed: float = 0.2
    grasp_offset: float = 0.075
    approach_distance: float = 0.12
    approach_height: float = 0.04
    close_radius: float = 0.28
    close_time: float = 0.25
    carry_forward: float = 0.15
    present_time: float = 0.8
    present_reach: float = 0.15

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            object.__setattr__(self, name, _setting(name, getattr(self, name)))


def _setting(name: str, value: object) -> float:
    """``value`` as a float if it is a valid person setting ``name`` (:data:`SETTING_RANGES`)."""
    lo, hi, unit, why = SETTING_RANGES[name]
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise ValueError(f"person setting {name} must be a number, got {value!r:.80}")
    x = float(value)
    if not (math.isfinite(x) and lo <= x <= hi):
        raise ValueError(
            f"person setting {name} must be {'' if math.isfinite(x) else 'finite and '}in "
            f"[{lo:.4g}, {hi:.4g}]{' ' + unit if unit else ''} ({why}), got {value!r}"
        )
    return x


def _option(name: str, value: object, bounds: tuple[float, float], unit: str) -> float:
    """A numeric reset option as a float: a real number (not a bool), finite, within bounds."""
    lo, hi = bounds
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise ValueError(f"{name} must be a number in [{lo:g}, {hi:g}] {unit}, got {value!r:.80}")
    x = float(value)
    if not (math.isfinite(x) and lo <= x <= hi):
        raise ValueError(f"{name} must be in [{lo:g}, {hi:g}] {unit}, got {value!r}")
    return x


def person_config(person: object, miss_distance: float) -> ReceiverConfig:
    """The env's ``person=`` overrides as a :class:`ReceiverConfig` (``give_up_behind`` defaults
    to the env's ``miss_distance``).

    Raises:
        ValueError: ``person`` is not a dict, names an unknown setting, or a value is not a
            number within its range (:data:`SETTING_RANGES`); the message names the setting.
    """
    if person is None:
        person = {}
    if not isinstance(person, Mapping):
        raise ValueError(
            f"person must be a dict of ReceiverConfig settings, got {type(person).__name__}"
        )
    known = ReceiverConfig.__dataclass_fields__
    unknown = sorted(repr(k) for k in person if not isinstance(k, str) or k not in known)
    if unknown:
        raise ValueError(
            f"unknown person setting(s) {unknown}; see handover_env.person.receiver.ReceiverConfig"
        )
    overrides = dict(person)
    if "give_up_behind" not in overrides:
        try:
            overrides["give_up_behind"] = _setting("give_up_behind", miss_distance)
        except ValueError as exc:
            raise ValueError(f"miss_distance (the person's give_up_behind): {exc}") from None
    return ReceiverConfig(**overrides)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) quaternions."""
    w1, x1, y1, z1 = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    w2, x2, y2, z2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[..., 1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[..., 2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[..., 3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    return out


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    """Rows of ``v`` scaled down to norm ``limit`` where longer."""
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return v * np.minimum(1.0, limit / np.maximum(norm, 1e-12))


class Receiver:
    """Drives the simulated person in a compiled handover scene.

    Args:
        model: the compiled scene (its receiver geometry is resized at every reset).
        ids: scene indices (``ids.body`` holds the receiver's).
        config: behaviour settings.
    """

    def __init__(
        self, model: mujoco.MjModel, ids: SceneIds, config: ReceiverConfig | None = None
    ) -> None:
        self.model, self.ids, self.body = model, ids, ids.body
        self.config = config or ReceiverConfig()
        self.grip = ArmGrip(
            model, int(ids.body.bodies[SEG["hand_r"]]), ids.body.grip_site, ids.object_body
        )
        self._v6 = np.zeros(6)
        self.motion: PersonMotion | None = None
        self.kind, self.source_id, self.hand_mode = "id", "", "reach"
        self.present_after_walk = False
        self._bound: mujoco.MjData | None = None
        self._reset_state()

    # ------------------------------------------------------------------ setup
    def reset(self, rng: np.random.Generator, kind: str = "id", height: float | None = None,
              speed: float | None = None, episode: Any = None, hand_mode: str = "reach",
              walker_overrides: dict | None = None, stop_x: float | None = None) -> None:
        """Choose the person for a new episode (validates everything before changing state).

        Args:
            rng: the env's ``np_random``.
            kind: ``"id"`` or ``"ood"`` scripted walker, or ``"replay"``.
            height: body height, m (scripted: fixes it; replay: default measured / 1.725).
            speed: nominal walking speed, m/s (scripted only).
            episode: for ``"replay"``: a ``Recording``, an ``Episode`` or a dict of arrays
                (``receiver_xy``, optionally ``receiver_pose``, ``source_id``).
            hand_mode: ``"reach"`` (modelled hand) or ``"recorded"`` (replay with a skeleton).
            walker_overrides: extra ``WalkerParams`` fields for scripted walkers.
            stop_x: static handover: stop at this pelvis x and present the hand.
        """
        if kind not in ("id", "ood", "replay"):
            raise ValueError(f"receiver must be 'id', 'ood' or 'replay', got {kind!r}")
        if hand_mode not in ("reach", "recorded"):
            raise ValueError(f"hand_mode must be 'reach' or 'recorded', got {hand_mode!r}")
        if height is not None:
            height = _option("height", height, HEIGHT_OPTION_RANGE, "m")
        if speed is not None:
            speed = _option("speed", speed, rm.SPEED_RANGE, "m/s")
        if kind == "replay":
            if episode is None:
                raise ValueError(
                    "receiver='replay' needs options['episode'] (a Recording, Episode or dict)"
                )
            motion = recorded_motion(episode, height)
            if hand_mode == "recorded" and not motion.has_skeleton:
                raise ValueError("hand_mode='recorded' needs the recorded skeleton (a Recording or "
                                 "a dict with 'receiver_pose')")
        else:
            if hand_mode == "recorded":
                raise ValueError("hand_mode='recorded' is for replayed receivers")
            motion = scripted_motion(rng, kind, height, speed, walker_overrides)
        self.t_depart = motion.t_depart
        if stop_x is not None:
            motion = stopped(motion, stop_x)
        self.motion = motion
        self.kind, self.hand_mode, self.source_id = kind, hand_mode, motion.source_id
        self.walker = motion.walker
        self.height = motion.dims.height
        self.present_after_walk = stop_x is not None
        apply_dims(self.model, self.body, motion.dims)
        self._lag, self._acc_gain = weld_lag_times(self.model, self.body)
        dims = motion.dims
        self._shoulder_local = dims.local(J["RIGHT_SHOULDER"], SEG["torso"])
        self._grip_local = dims.grip("r")
        self._arm_reach = float(
            np.linalg.norm(dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"]))
            + np.linalg.norm(dims.grip("r") + dims.local(J["RIGHT_WRIST"], SEG["forearm_r"]))
        )
        # Arm length as the recordings measure it (shoulder-elbow-wrist-hand joints) sets the
        # comfortable distance; the trunk's turn adds to the straight arm's reach.
        arm_length = sum(
            float(np.linalg.norm(dims.joints[j] - dims.joints[J[p]]))
            for j, p in (
                (J["RIGHT_ELBOW"], "RIGHT_SHOULDER"),
                (J["RIGHT_WRIST"], "RIGHT_ELBOW"),
                (J["RIGHT_HAND"], "RIGHT_WRIST"),
            )
        )
        self._comfort = self.config.comfort_fraction * arm_length
        self._max_reach = (STRAIGHT_ARM * self._arm_reach
                           + float(np.linalg.norm(self._shoulder_local)) * math.sin(TRUNK_MAX_TURN))
        self._reset_state()

    def _reset_state(self) -> None:
        self._grasp_side = 1.0  # +1: the hand takes the object's top part; -1: its bottom part
        self._object_axis = np.array([0.0, 0.0, 1.0])
        self.grip.active = False  # mj_resetData clears the grip's applied wrench
        self.grip.force[:] = 0.0
        self.state = "walking"
        self.tau = 0.0
        self.rho = 1.0
        self.t_grasp = math.nan
        self.t_reach = math.nan
        self.t_hand_raised = math.nan
        self.grasp_pelvis_xy = None
        self._hand: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._hand_goal_time = 0.0
        self._key0: tuple[np.ndarray, np.ndarray] | None = None
        self._key1: tuple[np.ndarray, np.ndarray] | None = None
        self._ticks: list[float] = [0.0]
        self._tick_i = 0
        self.reach_distance = 0.0
        self.arm_out_time = 0.0
        self.min_rho = 1.0
        self.path_deviation = 0.0
        self._released = False
        self._dt = 1.0 / RATE
        self._gripper: np.ndarray | None = None
        self._clear = False
        self._gripper_axis: np.ndarray | None = None

    # ------------------------------------------------------------------ queries
    @property
    def duration(self) -> float:
        """Length of the nominal motion, s (the playback may take longer when slowed)."""
        return 0.0 if self.motion is None else self.motion.duration

    @property
    def finished(self) -> bool:
        """True once the playback has reached the end of the nominal motion."""
        return self.motion is not None and self.tau >= self.motion.frames - 1

    @property
    def at_rest(self) -> bool:
        """True once a stopping person (static handover) stands still."""
        rest = None if self.motion is None else self.motion.rest_frame
        return rest is not None and self.tau >= rest

    @property
    def time_lost(self) -> float:
        """How far the person is behind their nominal walk, s."""
        return max(0.0, self._t - self.tau / RATE)

    def camera_xy(self) -> np.ndarray:
        """The pelvis xy a camera sees now (raw recorded track at the playback position)."""
        return self._interp(self.motion.camera_xy, self.tau)

    def base(self) -> tuple[float, float, float]:
        """Nominal pelvis x, y and walking heading at the playback position."""
        x, y = self._interp(self.motion.origin[:, 0, :2], self.tau)
        return float(x), float(y), float(self._interp(self.motion.heading, self.tau))

    @staticmethod
    def _interp(frames: np.ndarray, tau: float) -> np.ndarray:
        n = frames.shape[0]
        f = min(max(tau, 0.0), n - 1.0)
        i = min(int(f), n - 2)
        a = f - i
        return frames[i] * (1.0 - a) + frames[i + 1] * a

    # ------------------------------------------------------------------ per env step
    def start(self, data: mujoco.MjData) -> None:
        """Put the body at the start of its motion (call at reset, before ``mj_forward``)."""
        self._t = 0.0
        pose = self._pose_at(0.0, None)
        self._key0 = self._key1 = pose
        self._vel = np.zeros((len(pose[0]), 3))
        b = self.body
        data.qpos[b.root_qpos:b.root_qpos + 3] = pose[0][0]
        data.qpos[b.root_qpos + 3:b.root_qpos + 7] = pose[1][0]
        # Ball joints: the relative rotation of each segment to its parent.
        for i in range(1, len(pose[1])):
            parent = SEGMENTS[i].parent
            rel = _quat_mul(pose[1][parent] * np.array([1, -1, -1, -1]), pose[1][i])
            adr = int(self.model.jnt_qposadr[self.model.body_jntadr[b.bodies[i]]])
            data.qpos[adr:adr + 4] = rel
        data.qvel[b.dofs] = 0.0
        data.mocap_pos[b.mocap] = pose[0]
        data.mocap_quat[b.mocap] = pose[1]


    def plan_step(self, t0: float, t1: float, data: mujoco.MjData, object_pos: np.ndarray,
                  object_vel: np.ndarray, object_rot: np.ndarray, object_free: bool,
                  released: bool, gripper_pos: np.ndarray | None = None,
                  gripper_axis: np.ndarray | None = None) -> None:
        """Decide the body targets at the end of the env step [t0, t1] (once per 30 Hz step).

        Args:
            t0, t1: the env step.
            data: the simulation (read only: the body's actual pose, for the effort measures).
            object_pos, object_vel, object_rot: the object's position, velocity and rotation.
            object_free: the person does not hold the object yet.
            released: the gripper has opened.
            gripper_pos: the gripper's TCP (the hand avoids it and draws the object clear of it).
            gripper_axis: the gripper's approach axis (toward its fingertips) while it holds.
        """
        cfg = self.config
        dt = t1 - t0
        self._t = t0
        self._released = released
        self._gripper = None if gripper_pos is None else np.asarray(gripper_pos, dtype=np.float64)
        if self._gripper is not None and self.state == "holding" and released and not self._clear:
            self._clear = float(np.linalg.norm(object_pos - self._gripper)) > CLEAR_OF_GRIPPER
        self._gripper_axis = (
            None if gripper_axis is None else np.asarray(gripper_axis, dtype=np.float64)
        )
        self._object_axis = object_rot[:, 2].copy()
        grasp_point = object_pos + object_rot[:, 2] * (self._grasp_side * cfg.grasp_offset)
        # ---- how fast to walk on
        slow = False
        if object_free and self.state in ("walking", "reaching"):
            slow = self._should_slow(grasp_point, object_vel)
        target_rho = cfg.min_speed_factor if slow else 1.0
        step = cfg.slow_rate * dt
        self.rho = min(max(target_rho, self.rho - step), self.rho + step)
        self.min_rho = min(self.min_rho, self.rho)
        self.tau = min(self.tau + self.rho * dt * RATE, self.motion.frames - 1.0)
        # ---- what the hand does
        if object_free:
            self._decide(t1, grasp_point, object_vel)
        key = self._pose_at(self.tau, (grasp_point, object_vel, dt))
        self._key0, self._key1 = self._key1, key
        self._t = t1
        self._dt = dt

    def _body_frame(self, tau: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(right shoulder, walking direction (3,), walking speed) at playback position tau."""
        m = self.motion
        torso_q = self._interp(m.quat[:, SEG["torso"]], tau)
        torso = _quat_to_mat(torso_q / np.linalg.norm(torso_q))
        shoulder = self._interp(m.origin[:, SEG["torso"]], tau) + torso @ self._shoulder_local
        h = float(self._interp(m.heading, tau))
        u = np.array([math.cos(h), math.sin(h), 0.0])
        return shoulder, u, float(self._interp(m.speed, tau)) * self.rho

    def _meeting(
        self, grasp_point: np.ndarray, object_vel: np.ndarray
    ) -> tuple[float, float, float]:
        """Where the object is along the person's walk and when they would meet it.

        Returns:
            (forward offset of the grasp point from the right shoulder; time until it is
            ``meet_forward`` ahead of the pelvis if both keep their velocities along the walk;
            its distance from the shoulder then, with its current offset across the walk
            (sideways and up) and the meeting point's offset along it).
        """
        shoulder, u, v = self._body_frame(self.tau)
        pelvis = self._interp(self.motion.origin[:, 0], self.tau)
        rel = grasp_point - shoulder
        fwd = float(rel @ u)
        across = float(np.linalg.norm(rel - fwd * u))
        gap = float((grasp_point - pelvis) @ u) - self.config.meet_forward
        if gap <= 0.0:
            return fwd, 0.0, float(np.linalg.norm(rel))
        closing = v - float(object_vel @ u)
        if closing <= 1e-3:
            return fwd, math.inf, math.inf
        return fwd, gap / closing, math.hypot(across, fwd - gap)

    def _left_behind(self, fwd: float, dist: float) -> bool:
        """The person has walked past the object: it is ``give_up_behind`` behind the shoulder
        and they are beside it (not just heading elsewhere far from it)."""
        return fwd < -self.config.give_up_behind and dist < PASS_DISTANCE

    def _should_slow(self, grasp_point: np.ndarray, object_vel: np.ndarray) -> bool:
        cfg = self.config
        if self.present_after_walk:
            return False
        fwd, t_meet, dist = self._meeting(grasp_point, object_vel)
        if self._left_behind(fwd, dist):
            return False
        return t_meet <= cfg.reach_lead_time and dist > self._comfort

    def _decide(self, t: float, grasp_point: np.ndarray, object_vel: np.ndarray) -> None:
        cfg = self.config
        if self.state == "walking" and not self.present_after_walk and self.hand_mode == "reach":
            fwd, t_meet, dist = self._meeting(grasp_point, object_vel)
            if self._left_behind(fwd, dist):
                self._pass(t)
            elif t_meet <= cfg.reach_lead_time and dist <= self._max_reach:
                self._begin_reach(t, cfg.reach_duration)
        elif (
            self.state == "walking" and self.hand_mode == "recorded" and not self.present_after_walk
        ):
            grip = self._recorded_grip(self.tau)
            centre = grasp_point - self._object_axis * (self._grasp_side * cfg.grasp_offset)
            if np.linalg.norm(grip - centre) <= cfg.close_radius:
                # Close on the part of the object the hand comes from (its top or its bottom).
                self._grasp_side = (
                    1.0 if float((grip - centre) @ self._object_axis) >= 0.0 else -1.0
                )
                self._begin_reach(t, cfg.close_time)
        elif self.state == "walking" and self.present_after_walk and self.at_rest:
            self.state = "presenting"
            self._hand = self._swing_hand(self.tau)
            self._hand_goal_time = t + cfg.present_time
        elif self.state == "presenting" and t >= self._hand_goal_time:
            self.state = "presented"
            self.t_hand_raised = t
        elif (
            self.state == "presented"
            and np.linalg.norm(self._hand[0] - grasp_point) <= cfg.present_reach
        ):
            self._begin_reach(t, cfg.close_time)
        elif self.state == "reaching" and self.hand_mode == "reach" and not self.present_after_walk:
            fwd, _, dist = self._meeting(grasp_point, object_vel)
            if self._left_behind(fwd, dist):
                self._pass(t)

    def _pass(self, t: float) -> None:
        """The object is left behind: the person walks on (the arm returns to its swing)."""
        self.state = "passed"
        self._hand_goal_time = t + self.config.pull_time

    def _begin_reach(self, t: float, duration: float) -> None:
        if self._hand is None:  # start from where the arm is, at its current velocity
            if self.hand_mode == "recorded":
                p0, p1 = self._recorded_grip(self.tau), self._recorded_grip(self.tau + 1.0)
                self._hand = (p0, (p1 - p0) * RATE * self.rho, np.zeros(3))
            else:
                self._hand = self._swing_hand(self.tau)
        self.state = "reaching"
        self.t_reach = t
        self._hand_goal_time = t + duration

    def _pelvis(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nominal pelvis position, rotation and velocity at tau."""
        m = self.motion
        q = self._interp(m.quat[:, 0], tau)
        i = min(int(tau), m.frames - 2)
        vel = (m.origin[i + 1, 0] - m.origin[i, 0]) * RATE * self.rho
        return self._interp(m.origin[:, 0], tau), _quat_to_mat(q / np.linalg.norm(q)), vel

    def _swing_hand(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grip point of the walking swing at tau, with its velocity (zero acceleration)."""
        p0 = self._grip_from_arm(tau, self.motion.arm_swing)
        p1 = self._grip_from_arm(tau + 1.0, self.motion.arm_swing)
        return p0, (p1 - p0) * RATE * self.rho, np.zeros(3)

    def _arm_rotations(self, tau: float, arm: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        m = self.motion
        torso_q = self._interp(m.quat[:, SEG["torso"]], tau)
        torso = _quat_to_mat(torso_q / np.linalg.norm(torso_q))
        rel = self._interp(arm, tau)
        return torso, [torso @ rel[k] for k in range(3)]

    def _grip_from_arm(self, tau: float, arm: np.ndarray) -> np.ndarray:
        torso, rots = self._arm_rotations(tau, arm)
        m, dims = self.motion, self.motion.dims
        shoulder = self._interp(m.origin[:, SEG["torso"]], tau) + torso @ self._shoulder_local
        elbow = shoulder + rots[0] @ dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"])
        wrist = elbow + rots[1] @ dims.local(J["RIGHT_WRIST"], SEG["forearm_r"])
        return wrist + rots[2] @ self._grip_local

    def _recorded_grip(self, tau: float) -> np.ndarray:
        """Grip point of the recorded right arm at tau."""
        m = self.motion
        q = self._interp(m.quat[:, SEG["hand_r"]], tau)
        rot = _quat_to_mat(q / np.linalg.norm(q))
        return self._interp(m.origin[:, SEG["hand_r"]], tau) + rot @ self._grip_local

    def _hand_target(
        self, tau: float, grasp: tuple[np.ndarray, np.ndarray, float] | None
    ) -> np.ndarray | None:
        """Advance the modelled hand one env step; None when the arm follows the nominal motion."""
        cfg = self.config
        state = self.state
        if state == "walking" or (state == "passed" and self._hand is None):
            return None
        if grasp is None:
            return self._hand[0] if self._hand is not None else None
        grasp_point, object_vel, dt = grasp
        shoulder, _, _ = self._body_frame(tau)
        if state == "reaching":
            # Approach the grasp point from the person's side and a little above: aim at a point
            # ``approach_distance`` toward the shoulder (horizontally) and ``approach_height`` up,
            # and close in over the last ``close_time``, so the hand does not sweep through the
            # gripper holding the object.
            away = shoulder - grasp_point
            away[2] = 0.0
            if self._gripper_axis is not None:
                # From the fingertips' side of the gripper, if that side faces the person.
                axis = self._gripper_axis.copy()
                axis[2] = 0.0
                if float(axis @ away) > 0.0:
                    away = axis
            norm = float(np.linalg.norm(away))
            if float(np.linalg.norm(grasp_point - shoulder)) > self._max_reach:
                # Out of reach: hold the hand ready in front of the object; close in only once
                # it can be taken.
                self._hand_goal_time = max(self._hand_goal_time, self._t + cfg.close_time)
            remaining = self._hand_goal_time - self._t
            w = min(max(remaining / cfg.close_time, 0.0), 1.0)
            w = w * w * (3.0 - 2.0 * w)
            offset = away * (cfg.approach_distance * w / norm) if norm > 1e-6 else np.zeros(3)
            offset[2] = self._grasp_side * cfg.approach_height * w
            goal, goal_v = grasp_point + offset, object_vel
        elif state == "holding" and self._t < self.t_grasp + cfg.hold_time:
            # The arm stays out, moving with the body (the shared hold of the recordings).
            pelvis, rot, vel = self._pelvis(tau)
            goal, goal_v = pelvis + rot @ self._hold_rel, vel
        elif state == "holding" and not self._clear:
            # Draw the object out toward the body at the height it is held, not down across the
            # gripper's fingers, until it is clear of the gripper.
            pelvis, rot, vel = self._pelvis(tau)
            pull = self._hold_rel.copy()
            reach = float(np.linalg.norm(pull[:2]))
            pull[:2] *= max(reach - cfg.pull_distance, min(reach, CARRY_CLEARANCE)) / max(
                reach, 1e-6
            )
            goal, goal_v = pelvis + rot @ pull, vel
        elif state == "holding":
            swing = self._swing_hand(tau)
            _, u, _ = self._body_frame(tau)
            goal, goal_v = swing[0] + cfg.carry_forward * u, swing[1]
        elif state in ("presenting", "presented"):
            torso, _ = self._arm_rotations(tau, self.motion.arm_swing)
            goal, goal_v = shoulder + torso @ np.asarray(PRESENT_OFFSET), np.zeros(3)
        else:  # passed: the hand returns to the swing
            goal, goal_v = self._swing_hand(tau)[:2]
        if state == "holding" and self._t < self.t_grasp + cfg.hold_time:
            # Settle onto the body-fixed hold over the hold time (no yank to catch up).
            remaining = max(self.t_grasp + cfg.hold_time - self._t, HOLD_TRACKING)
        elif state == "passed":
            remaining = max(self._hand_goal_time - self._t, cfg.pull_time)
        else:
            remaining = max(self._hand_goal_time - self._t, 0.1)
        # Aim where the goal will be when the movement ends (it moves on at goal_v).
        x, v, a = min_jerk_step(*self._hand, goal + goal_v * remaining, goal_v, remaining, dt)
        off = x - shoulder
        dist = float(np.linalg.norm(off))
        if dist > self._arm_reach:
            x = shoulder + off * (self._arm_reach / dist)
        self._hand = (x, v, a)
        return x

    def _pose_at(self, tau: float, grasp: tuple | None) -> tuple[np.ndarray, np.ndarray]:
        """Segment origins (S, 3) and quaternions (S, 4) at playback position tau."""
        m = self.motion
        origin = self._interp(m.origin, tau)
        quat = self._interp(m.quat, tau)
        quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
        hand = self._hand_target(tau, grasp)
        arm = None
        if hand is not None:
            self._lean_toward(origin, quat, hand)
            torso = _quat_to_mat(quat[SEG["torso"]])
            shoulder = origin[SEG["torso"]] + torso @ self._shoulder_local
            # A hand held out toward an object is level, pointing away from the shoulder.
            level = hand - shoulder
            level[2] = 0.0
            n = float(np.linalg.norm(level))
            arm = arm_pose(shoulder, torso, hand, m.dims, level / n if n > 0.05 else None)
        elif self.hand_mode == "reach":
            torso = _quat_to_mat(quat[SEG["torso"]])
            rel = self._interp(m.arm_swing, tau)
            arm = tuple(torso @ rel[k] for k in range(3))
        if arm is not None:
            dims = m.dims
            rot_q = mat_to_quat(np.stack(arm))
            prev = quat[list(RIGHT_ARM)]
            rot_q *= np.where(np.sum(rot_q * prev, axis=-1, keepdims=True) < 0, -1.0, 1.0)
            quat[list(RIGHT_ARM)] = rot_q
            torso = _quat_to_mat(quat[SEG["torso"]])
            shoulder = origin[SEG["torso"]] + torso @ self._shoulder_local
            elbow = shoulder + arm[0] @ dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"])
            wrist = elbow + arm[1] @ dims.local(J["RIGHT_WRIST"], SEG["forearm_r"])
            origin[RIGHT_ARM[0]], origin[RIGHT_ARM[1]], origin[RIGHT_ARM[2]] = (
                shoulder,
                elbow,
                wrist,
            )
        return origin, quat

    def _lean_toward(self, origin: np.ndarray, quat: np.ndarray, hand: np.ndarray) -> None:
        """Turn and lean the upper body toward a hand target beyond the straight arm's reach.

        People reaching far bring their shoulder toward the target by turning and leaning the
        trunk. The torso (with the head and arms) rotates about its base toward the target by
        the smallest rotation that brings the shoulder close enough, at most ``TRUNK_MAX_TURN``
        (modifies ``origin`` and ``quat`` in place).
        """
        base = origin[SEG["torso"]]
        torso = _quat_to_mat(quat[SEG["torso"]])
        s = torso @ self._shoulder_local
        need = float(np.linalg.norm(base + s - hand)) - STRAIGHT_ARM * self._arm_reach
        if need <= 0.0:
            return
        h = hand - base
        axis = np.cross(s, h)
        n = float(np.linalg.norm(axis))
        if n < 1e-9:
            return
        angle = min(need / float(np.linalg.norm(s)), TRUNK_MAX_TURN)
        half = 0.5 * angle
        dq = np.concatenate([[math.cos(half)], axis / n * math.sin(half)])
        rot = _quat_to_mat(dq)
        for i in _UPPER_BODY:
            quat[i] = _quat_mul(dq, quat[i])
            origin[i] = base + rot @ (origin[i] - base)

    # ------------------------------------------------------------------ per tick
    def plan_ticks(self, alphas: list[float]) -> None:
        """The fractions of this env step at which controller ticks fall; prepares the step's
        target interpolation (start pose and increment, velocity feed-forward included)."""
        self._ticks = alphas
        self._tick_i = 0
        dt = 1.0 / RATE
        (o0, q0), (o1, q1) = self._key0, self._key1
        # Angular velocity from q0 -> q1 (world frame): 2 log(q1 q0^-1) / dt.
        dq = _quat_mul(q1, q0 * _CONJ)
        dq *= np.where(dq[:, :1] < 0, -1.0, 1.0)
        # Velocity feed-forward: a weld with damping b and stiffness k lags a target moving at v
        # by (b / k) v, so the target is placed that far ahead (the segment then sits on the
        # nominal pose and its weld force is zero in free motion). The feed-forward rotation is
        # constant over the step, so it is applied to both keyframes once here.
        lag = self._lag[:, None]
        ff_q = np.concatenate([np.ones((len(lag), 1)), dq[:, 1:] * (lag / dt)], axis=1)
        vel = (o1 - o0) / dt
        acc = (vel - self._vel) / dt
        self._vel = vel
        # The feed-forward assumes human speeds and accelerations (a recorded arm can be tracked
        # at several m/s for a frame or two): beyond them a segment lags its recorded motion
        # instead of being pulled by a target far ahead of it.
        self._pos0 = (o0 + _clip_norm(vel, MAX_SEGMENT_SPEED) * lag
                      + _clip_norm(acc, MAX_SEGMENT_ACCEL) * self._acc_gain[:, None])
        self._dpos = o1 - o0
        self._quat0 = _quat_mul(ff_q, q0)
        self._dquat = _quat_mul(ff_q, q1) - self._quat0

    def apply_tick(self, data: mujoco.MjData) -> None:
        """Move the targets to their pose at the next tick (linear between the step's keyframes)."""
        a = self._ticks[self._tick_i] if self._tick_i < len(self._ticks) else 1.0
        self._tick_i += 1
        self._set_targets(data, a)

    def apply(self, data: mujoco.MjData, alpha: float) -> None:
        self._set_targets(data, alpha)

    def _set_targets(self, data: mujoco.MjData, a: float) -> None:
        """Targets at the fraction ``a`` of the step (MuJoCo normalises mocap quaternions)."""
        if data is not self._bound:
            self._bound = data
            self._mocap_pos = data.mocap_pos[self.body.mocap]
            self._mocap_quat = data.mocap_quat[self.body.mocap]
        np.multiply(self._dpos, a, out=self._mocap_pos)
        self._mocap_pos += self._pos0
        np.multiply(self._dquat, a, out=self._mocap_quat)
        self._mocap_quat += self._quat0

    def end_step(self, data: mujoco.MjData) -> None:
        """The env step's physics is done: record the person's effort over it."""
        self._track_effort(data, self._dt)

    # ------------------------------------------------------------------ grasp
    def grasp_point(self, data: mujoco.MjData) -> np.ndarray:
        """Where the hand holds the object: on its axis, ``grasp_offset`` from its centre."""
        ob = self.ids.object_body
        return data.xpos[ob] + data.xmat[ob].reshape(3, 3)[:, 2] * (
            self._grasp_side * self.config.grasp_offset
        )

    @property
    def holding(self) -> bool:
        """True while the person's hand holds the object."""
        return self.grip.active

    def try_grasp(self, model: mujoco.MjModel, data: mujoco.MjData) -> bool:
        """Grasp if the grip point is at the object's grasp point and moves with it (within
        ``grasp_radius`` and ``grasp_speed``). Returns True on grasp."""
        if self.state != "reaching":
            return False
        cfg = self.config
        grip = data.site_xpos[self.body.grip_site]
        if np.linalg.norm(grip - self.grasp_point(data)) > cfg.grasp_radius:
            return False
        v = self._v6
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, self.body.grip_site, v, 0)
        v_grip = v[3:].copy()
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, self.ids.object_body, v, 0)
        if np.linalg.norm(v_grip - v[3:]) > cfg.grasp_speed:
            return False
        self.grip.close(data, np.array([0.0, 0.0, self._grasp_side * cfg.grasp_offset]))
        self.state = "holding"
        self.t_grasp = float(data.time)
        self.grasp_pelvis_xy = data.xpos[self.body.bodies[0], :2].copy()
        pelvis, rot, _ = self._pelvis(self.tau)
        self._hold_rel = (
            rot.T @ (self._hand[0] - pelvis) if self._hand is not None else rot.T @ (grip - pelvis)
        )
        self._hand_goal_time = self.t_grasp + self.config.hold_time + self.config.pull_time
        return True

    # ------------------------------------------------------------------ effort
    def _track_effort(self, data: mujoco.MjData, dt: float) -> None:
        b = self.body
        if self.state in ("reaching", "presenting", "presented") or (
            self.state == "holding" and not self._released
        ):
            self.arm_out_time += dt
            shoulder = data.xpos[b.bodies[RIGHT_ARM[0]]]
            grip = data.site_xpos[b.grip_site]
            self.reach_distance = max(self.reach_distance, float(np.linalg.norm(grip - shoulder)))
        target = self._key1[0][0]  # the nominal pelvis at the end of this step
        pelvis = data.xpos[b.bodies[0]]
        self.path_deviation = max(self.path_deviation, float(np.hypot(*(pelvis[:2] - target[:2]))))

    def effort(self) -> dict[str, float]:
        """The person's effort so far (see the module docstring)."""
        return {
            "reach_distance": self.reach_distance,
            "arm_extended_time": self.arm_out_time,
            "time_lost": self.time_lost,
            "min_speed_factor": self.min_rho,
            "path_deviation": self.path_deviation,
        }
