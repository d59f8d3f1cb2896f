"""The simulated person during an episode: walks on, reaches, grasps, holds and pulls.

This module decides, at the env's 30 Hz, what the person does and where the hand goes
(:class:`~handover_env.person.settings.ReceiverConfig` holds the settings); the body is posed for
it by :mod:`~handover_env.person.pose` and moved by :mod:`~handover_env.person.targets`:

* **Walking.** The nominal motion (:class:`handover_env.person.person.PersonMotion`: a recorded
  person or the scripted walker) is played back at a speed factor rho (1 = as recorded). A person
  waiting for an object they cannot reach yet slows down (rho falls at ``slow_rate`` per second, not
  below ``min_speed_factor``) and speeds up again once it is within reach; the camera sees the
  pelvis of this played-back walk.
* **Reaching** (``hand_mode="reach"``, the modelled hand): the decisions look along the
  person's own remaining walk (:mod:`handover_env.person.receiver_rules`: pauses, loops and
  turn-backs included). The person reaches when they will meet the object within
  ``reach_lead_time``: when its grasp point (moving on at its velocity) comes within their take
  distance of the right shoulder, not behind it. The take distance grows with how far the object
  is held from their path (its closest approach; fitted to the recordings), so a person reaches
  as far as they need to, not always to full extension, plus (person switch ``reach_offset``, on
  by default) the person's own reach offset (:mod:`handover_env.person.take`: drawn for a
  scripted walker, the recorded person's own for a replayed recording); it is fixed at the reach
  onset. The hand then moves on a minimum-jerk path re-planned every step toward the moving
  grasp point (Hoff & Arbib 1993) on the object's lower part (person switch ``grasp_below``, on
  by default; its top part when off), planned to arrive at the meeting (at most
  ``reach_duration`` after the onset; put off only when the meeting comes over ``REPLAN_SLACK``
  later, brought forward whenever it comes earlier). The arm follows by two-link inverse
  kinematics (:func:`handover_env.person.gait.arm_pose`). With the person switch ``arm_yield``
  (on by default) it yields to the robot (:mod:`handover_env.person.arm_yield`): touched, it
  pushes at most as hard as a human arm and stops pushing after the tactile latency, and the
  reach starts again from where the hand is.
* **Calibrated range**: at reset the person's walk is measured against the walks the person was
  calibrated on (:mod:`handover_env.person.walk_range`); :meth:`Receiver.warn_outside` warns
  once per receiver (so once per env) and ``calibration.within`` is the env's
  ``info["within_calibration"]``. Nothing is refused.
* **Left behind** (``passed``, the env's ``missed``): the unheld object is ``give_up_behind``
  behind the shoulder within ``PASS_DISTANCE``, and at no later point of the remaining walk is it
  ahead of them again (:func:`~handover_env.person.receiver_rules.left_behind`); run on the
  recordings, this never fires before a recorded transfer
  (``docs/calibration/receiver_calibration.md``).
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

Effort (``effort()``): :class:`handover_env.person.effort.Effort`'s measures (``reach_distance``:
the shoulder-object distance when the person took the object, defined as for the recordings),
plus the time lost to slowing down and the slowest speed factor.

The module is over 500 lines because the decisions, the hand's path and the grasp read and write
one person's per-step state (playback position, speed factor, hand state); the decision rules
themselves are the pure functions of :mod:`handover_env.person.receiver_rules`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from handover_env.person import hand_path as hp
from handover_env.person import motion as rm
from handover_env.person import path_ahead as pa
from handover_env.person.body_model import BodyIds, apply_dims, set_joint_damping
from handover_env.person.calibrated_range import warning_text
from handover_env.person.effort import Effort
from handover_env.person.grip import ArmGrip
from handover_env.person.person import RATE, PersonMotion, recorded_motion, scripted_motion, stopped
from handover_env.person.pose import (
    STRAIGHT_ARM,
    TRUNK_MAX_TURN,
    MotionPose,
    frame_weight,
    interp,
)
from handover_env.person.posing import ELBOW_POLE_OUT, ELBOW_POLE_RECORDED
from handover_env.person.receiver_rules import Meeting
from handover_env.person.rotations import length
from handover_env.person.settings import (
    HEIGHT_OPTION_RANGE,
    PASS_DISTANCE,
    ReceiverConfig,
    check_option,
)
from handover_env.person.skeleton import SEG, J
from handover_env.person.take import PersonOffset, person_offset
from handover_env.person.targets import BodyTargets
from handover_env.person.walk_range import WalkCheck, walk_check

CAMERA_RATE = RATE
STATES = ("walking", "reaching", "holding", "presenting", "presented", "passed")
#: A reaching hand's planned arrival is put off only if the meeting comes later than planned by
#: more than this, s (about the recorded receivers' median |Δt| of the simulated transfer, 0.2 s).
REPLAN_SLACK = 0.2
#: Shortest re-planning horizon of a hand that holds a point fixed to the body, s.
HOLD_TRACKING = 0.3
#: A hand drawing an object out keeps it this far from the pelvis axis (horizontally), m: the
#: held bottle stays clear of the torso.
CARRY_CLEARANCE = 0.35
#: A held object counts as out of the (released) gripper once its centre is this far from the
#: TCP (m): the bottle's radius plus the open fingers' depth.
CLEAR_OF_GRIPPER = 0.1
#: Where the static receiver holds the raised right hand: forward, right and up from the
#: shoulder in the body frame, m (a hand held out in front, below shoulder height).
PRESENT_OFFSET = (0.30, -0.15, -0.15)
#: The hand's state codes for :func:`handover_env.person.hand_path.hand_kernel`.
HAND_STATES = {"reaching": hp.REACHING, "holding": hp.HOLDING, "presenting": hp.PRESENTING,
               "presented": hp.PRESENTING, "passed": hp.PASSED}


@dataclass(frozen=True)
class ReceiverIds:
    """The indices of a compiled scene that the receiver reads, handed over by the scene
    (:attr:`handover_env.robot.scene.SceneIds.receiver`).

    Attributes:
        body: the person's bodies, joints, welds, sites and geoms.
        object_body: the handed-over object's body.
    """

    body: BodyIds
    object_body: int


class Receiver:
    """Drives the simulated person in a compiled handover scene.

    Args:
        model: the compiled scene (its receiver geometry is resized at every reset).
        ids: the scene indices the person reads (its body's and the object's).
        config: behaviour settings.
    """

    def __init__(
        self, model: mujoco.MjModel, ids: ReceiverIds, config: ReceiverConfig | None = None
    ) -> None:
        self.model, self.ids, self.body = model, ids, ids.body
        self.config = config or ReceiverConfig()
        self.grip = ArmGrip(
            model, int(ids.body.bodies[SEG["hand_r"]]), ids.body.grip_site, ids.object_body
        )
        self._v6 = np.zeros(6)
        self._grasp_bound: mujoco.MjData | None = None
        self._judge_io = np.zeros(pa.IO_SIZE)
        self._hand_io = np.zeros(hp.IO_SIZE)
        self.motion: PersonMotion | None = None
        self.kind, self.source_id, self.hand_mode = "id", "", "reach"
        self.present_after_walk = False
        set_joint_damping(model, ids.body, self.config.joint_damping)
        self.targets = BodyTargets(model, ids.body, arm_yield=self.config.arm_yield)
        self._pelvis_target = self.targets.key1[0][0]  # a view: the nominal pelvis at step end
        self.measured = Effort(ids.body)
        self.pose: MotionPose | None = None
        #: This person's own reach offset (origin ``"off"`` unless ``config.reach_offset``).
        self.reach_offset = PersonOffset(0.0, "off")
        #: This person's walk against the calibrated range.
        self.calibration = WalkCheck({}, [])
        self._warned_calibration = False
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
            height = check_option("height", height, HEIGHT_OPTION_RANGE, "m")
        if speed is not None:
            speed = check_option("speed", speed, rm.SPEED_RANGE, "m/s")
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
        offset = (person_offset(rng, kind, episode) if self.config.reach_offset
                  else PersonOffset(0.0, "off"))
        calibrated = walk_check(motion, kind, episode, height)
        self.t_depart = motion.t_depart
        if stop_x is not None:
            motion = stopped(motion, stop_x)
        self.motion = motion
        self._camera_xy = np.zeros(2)  # camera_xy's result
        self.reach_offset = offset
        self.calibration = calibrated
        self.kind, self.hand_mode, self.source_id = kind, hand_mode, motion.source_id
        self.walker = motion.walker
        self.height = motion.dims.height
        self.present_after_walk = stop_x is not None
        apply_dims(self.model, self.body, motion.dims)
        self.targets.resize()
        dims = motion.dims
        self.pose = MotionPose(motion, ELBOW_POLE_RECORDED if self.config.recorded_elbow
                               else ELBOW_POLE_OUT)
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
        self._max_reach = (STRAIGHT_ARM * self.pose.arm_reach
                           + float(np.linalg.norm(self.pose.shoulder_local))
                           * math.sin(TRUNK_MAX_TURN))
        self._track, self._path = pa.track_rows(*self.pose.shoulder_track())
        io = self._judge_io
        io[pa.MIN_SPEED], io[pa.BEHIND], io[pa.WITHIN] = (
            self.config.min_speed_factor, self.config.give_up_behind, PASS_DISTANCE)
        io[pa.REACH], io[pa.LEAD], io[pa.COMFORT] = (
            self._max_reach, self.config.reach_lead_time, self._comfort)
        io[pa.OFFSET] = offset.value
        hp.hand_settings(self._hand_io, self.config, self._max_reach, self.pose.arm_reach, RATE,
                         HOLD_TRACKING, CARRY_CLEARANCE, PRESENT_OFFSET, CLEAR_OF_GRIPPER)
        self._reset_state()

    def _reset_state(self) -> None:
        # +1: the hand takes the object's top part; -1: its lower part (grasp_below)
        self._grasp_side = -1.0 if self.config.grasp_below else 1.0
        self._object_axis = np.array([0.0, 0.0, 1.0])
        self.grip.active = False  # mj_resetData clears the grip's applied wrench
        self.grip.force[:] = 0.0
        self.state = "walking"
        self.tau = 0.0
        self.rho = 1.0
        self.t_grasp = math.nan
        self.t_reach = math.nan
        self.reach_plan: Meeting | None = None
        self.t_hand_raised = math.nan
        self.grasp_pelvis_xy = None
        #: at the grasp: the bottle's centre in the walking frame (forward, left, up from the
        #: pelvis; as the recordings' object_fwd/lat/up_transfer) and its speed (m/s)
        self.grasp_object_body: tuple[float, float, float] | None = None
        self.grasp_object_speed = math.nan
        self._hand: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        #: the hand state _hand_target last read out of its io (still there while it is _hand)
        self._hand_out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._hand_goal_time = 0.0
        self.targets.reset()
        self.measured.reset()
        self.min_rho = 1.0
        self._released = False
        self._dt = 1.0 / RATE
        self._gripper: np.ndarray | None = None
        self._clear = False
        self._gripper_axis: np.ndarray | None = None
        #: avoid_gripper: the gripper's axis as it last held the object, the hand's depth along
        #: it at the grasp, and when the draw-out started (inf: not yet)
        self._out_axis: np.ndarray | None = None
        self._out_depth = 0.0
        self._t_out = math.inf
        self._left = False
        #: this step's meeting (:func:`~handover_env.person.receiver_rules.meeting_of`'s fields:
        #: time, distance, closest, take, reachable)
        self._meet: tuple[float, float, float, float, bool] | None = None

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
        """The pelvis xy a camera sees now (raw recorded track at the playback position).

        :func:`~handover_env.person.pose.interp`'s value (the same two products and sum per
        coordinate), computed on floats into a (2,) array the receiver keeps: the env asks for
        it at every 30 Hz step; copy it to keep it past the next call.
        """
        frames = self.motion.camera_xy
        i, a = frame_weight(frames.shape[0], self.tau)
        b = 1.0 - a
        (x0, y0), (x1, y1) = frames[i:i + 2].tolist()
        out = self._camera_xy
        out[0] = x0 * b + x1 * a
        out[1] = y0 * b + y1 * a
        return out

    def base(self) -> tuple[float, float, float]:
        """Nominal pelvis x, y and walking heading at the playback position."""
        x, y = interp(self.motion.origin[:, 0, :2], self.tau)
        return float(x), float(y), float(interp(self.motion.heading, self.tau))

    # ------------------------------------------------------------------ per env step
    def start(self, data: mujoco.MjData) -> None:
        """Put the body at the start of its motion (call at reset, before ``mj_forward``)."""
        self._t = 0.0
        self.targets.start(data, self._pose_at(0.0, None))

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
        if self.targets.arm.end_step() and self.state == "reaching" and self._hand is not None:
            # The robot stopped the arm: the reach starts again from where the hand is.
            self._hand = (data.site_xpos[self.body.grip_site].copy(), np.zeros(3), np.zeros(3))
        self._gripper = None if gripper_pos is None else np.asarray(gripper_pos, dtype=np.float64)
        if self._gripper is not None and self.state == "holding" and released and not self._clear:
            self._clear = length(object_pos - self._gripper) > CLEAR_OF_GRIPPER
        self._gripper_axis = (
            None if gripper_axis is None else np.asarray(gripper_axis, dtype=np.float64)
        )
        if cfg.avoid_gripper and self.state == "holding":
            self._note_gripper(t0, released)
        (_, _, ax), (_, _, ay), (_, _, az) = object_rot.tolist()
        self._object_axis = np.array((ax, ay, az))
        grasp_point = np.array(self._grasp_xyz(object_pos.tolist(), (ax, ay, az)))
        if object_free and not self.present_after_walk and self.state in ("walking", "reaching"):
            self._judge(grasp_point, object_vel)
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
        self._pose_at(self.tau, (grasp_point, object_vel, dt), self.targets.next_key())
        self._t = t1
        self._dt = dt

    def _judge(self, grasp_point: np.ndarray, object_vel: np.ndarray) -> None:
        """This step's two judgements of the object on the person's remaining nominal path, from
        the playback position on, timed at the current speed factor
        (:func:`~handover_env.person.path_ahead.judge_kernel`): whether it is left behind for good
        (:func:`~handover_env.person.receiver_rules.left_behind`: ``give_up_behind`` behind the
        shoulder within ``PASS_DISTANCE``, and the rest of the walk never brings it ahead again),
        and when and how far from the shoulder they will meet it
        (:func:`~handover_env.person.receiver_rules.meet`, the object extrapolated over the reach
        lead time; a reaching person keeps the closest approach and the take distance of their
        reach onset)."""
        io = self._judge_io
        io[pa.TAU], io[pa.RHO] = self.tau, self.rho
        io[pa.OBJ:pa.OBJ + 3], io[pa.OBJ_VEL:pa.OBJ_VEL + 3] = grasp_point, object_vel
        io[pa.CLOSEST] = io[pa.TAKE] = -1.0
        if self.state == "reaching" and self.reach_plan is not None:
            io[pa.CLOSEST], io[pa.TAKE] = self.reach_plan.closest, self.reach_plan.take
        pa.judge_kernel(self._track, self._path, io)
        # LEFT, then the meeting's five values (meeting_of's fields; a Meeting is built only
        # when the hand's plan keeps one)
        left, t, distance, closest, take, reachable = io[pa.LEFT:pa.MEETING + 5].tolist()
        self._left = left > 0.0
        self._meet = (t, distance, closest, take, reachable > 0.0)

    def _should_slow(self, grasp_point: np.ndarray, object_vel: np.ndarray) -> bool:
        """Slow down: the person is about to meet the object (within the reach lead time) farther
        than is comfortable, or to pass it out of reach."""
        if self.present_after_walk or self._left:
            return False
        t, distance = self._meet[:2]
        return t <= self.config.reach_lead_time and distance > self._comfort

    def _decide(self, t: float, grasp_point: np.ndarray, object_vel: np.ndarray) -> None:
        cfg = self.config
        if self.state == "walking" and not self.present_after_walk and self.hand_mode == "reach":
            if self._left:
                self._pass(t)
                return
            m_time, _, _, _, reachable = self._meet
            if reachable and m_time <= cfg.reach_lead_time:
                self._begin_reach(t, min(max(m_time, cfg.close_time), cfg.reach_duration))
                self.reach_plan = Meeting(*self._meet)
        elif (
            self.state == "walking" and self.hand_mode == "recorded" and not self.present_after_walk
        ):
            grip = self.pose.recorded_grip(self.tau)
            centre = grasp_point - self._object_axis * (self._grasp_side * cfg.grasp_offset)
            if length(grip - centre) <= cfg.close_radius:
                # Close on the part of the object the hand comes from (its top or its bottom).
                self._grasp_side = (
                    1.0 if float((grip - centre) @ self._object_axis) >= 0.0 else -1.0
                )
                self._begin_reach(t, cfg.close_time)
        elif self.state == "walking" and self.present_after_walk and self.at_rest:
            self.state = "presenting"
            self._hand = self.pose.swing_hand(self.tau, self.rho)
            self._hand_goal_time = t + cfg.present_time
        elif self.state == "presenting" and t >= self._hand_goal_time:
            self.state = "presented"
            self.t_hand_raised = t
        elif (
            self.state == "presented"
            and length(self._hand[0] - grasp_point) <= cfg.present_reach
        ):
            self._begin_reach(t, cfg.close_time)
        elif self.state == "reaching" and self.hand_mode == "reach" and not self.present_after_walk:
            if self._left:
                self._pass(t)
                return
            # Re-plan the hand's arrival for the meeting: earlier as soon as it comes earlier,
            # later only when it is put off by more than REPLAN_SLACK (the person pauses or turns
            # away, or the object is taken back), not for the last centimetres of an object that
            # moves on with the walk.
            m_time, distance, _, take, reachable = self._meet
            goal = t + m_time
            if reachable and (goal < self._hand_goal_time
                              or goal > self._hand_goal_time + REPLAN_SLACK):
                self._hand_goal_time = goal
                self.reach_plan = Meeting(m_time, distance, self.reach_plan.closest, take,
                                          True) if self.reach_plan is not None else (
                                              Meeting(*self._meet))

    def _note_gripper(self, t: float, released: bool) -> None:
        """``avoid_gripper``: while the person holds the object, remember the gripper's approach
        axis as it last held it and the hand's depth along it at the grasp, and when the draw-out
        starts: the first step that sees the gripper open (the hand's pull, which opened it, goes
        on by the open side; :func:`~handover_env.person.hand_path.hand_kernel`)."""
        if self._gripper_axis is not None and self._gripper is not None:
            if self._out_axis is None and self._hand is not None:
                self._out_depth = float((self._hand[0] - self._gripper) @ self._gripper_axis)
            self._out_axis = self._gripper_axis
        if released and math.isinf(self._t_out):
            self._t_out = t

    def _pass(self, t: float) -> None:
        """The object is left behind: the person walks on (the arm returns to its swing)."""
        self.state = "passed"
        self._hand_goal_time = t + self.config.pull_time

    def _begin_reach(self, t: float, duration: float) -> None:
        if self._hand is None:  # start from where the arm is, at its current velocity
            if self.hand_mode == "recorded":
                p0, p1 = self.pose.recorded_grip(self.tau), self.pose.recorded_grip(self.tau + 1.0)
                self._hand = (p0, (p1 - p0) * RATE * self.rho, np.zeros(3))
            else:
                self._hand = self.pose.swing_hand(self.tau, self.rho)
        self.state = "reaching"
        self.t_reach = t
        self._hand_goal_time = t + duration

    def _hand_target(
        self, tau: float, grasp: tuple[np.ndarray, np.ndarray, float] | None
    ) -> np.ndarray | None:
        """Advance the modelled hand one env step; None when the arm follows the nominal motion."""
        state = self.state
        if state == "walking" or (state == "passed" and self._hand is None):
            return None
        if grasp is None:
            return self._hand[0] if self._hand is not None else None
        grasp_point, object_vel, dt = grasp
        io = self._hand_io
        io[hp.STATE] = HAND_STATES[state]
        io[hp.TAU], io[hp.RHO], io[hp.NOW], io[hp.DT] = tau, self.rho, self._t, dt
        io[hp.T_GRASP], io[hp.CLEAR], io[hp.SIDE] = self.t_grasp, self._clear, self._grasp_side
        if self._gripper_axis is None:
            io[hp.HAS_AXIS] = 0.0
        else:
            io[hp.HAS_AXIS] = 1.0
            io[hp.AXIS:hp.AXIS + 3] = self._gripper_axis
        io[hp.GRASP:hp.GRASP + 3], io[hp.OBJ_VEL:hp.OBJ_VEL + 3] = grasp_point, object_vel
        if state == "holding":
            io[hp.HOLD_REL:hp.HOLD_REL + 3] = self._hold_rel
            io[hp.T_OUT] = self._t_out
            if self._out_axis is not None and self._gripper is not None:
                io[hp.HAS_GRIP], io[hp.DEPTH] = 1.0, self._out_depth
                io[hp.GRIP_AXIS:hp.GRIP_AXIS + 3], io[hp.TCP:hp.TCP + 3] = (
                    self._out_axis, self._gripper)
            else:
                io[hp.HAS_GRIP] = 0.0
        if self._hand is not self._hand_out:  # else io holds it: the kernel's last output
            x, v, a = self._hand
            io[hp.X:hp.X + 3], io[hp.V:hp.V + 3], io[hp.A:hp.A + 3] = x, v, a
        io[hp.GOAL_TIME] = self._hand_goal_time
        hp.hand_kernel(self.pose.rows, self.pose.io, io)
        self._hand_goal_time = float(io[hp.GOAL_TIME])
        xva = io[hp.X:hp.A + 3].copy()  # X, V, A are consecutive
        self._hand = self._hand_out = (xva[:3], xva[3:6], xva[6:])
        return self._hand[0]

    def _pose_at(self, tau: float, grasp: tuple | None,
                 out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Segment origins (S, 3) and quaternions (S, 4) at playback position tau, the modelled
        hand advanced by one env step (written into ``out`` (S, 7) when given)."""
        hand = self._hand_target(tau, grasp)
        return self.pose.at(tau, hand, swing_arm=self.hand_mode == "reach", out=out)

    def warn_outside(self, seed: int | None) -> None:
        """Warn once per receiver (so once per env) when this episode's person walks outside the
        calibrated range (:mod:`handover_env.person.walk_range`); nothing is refused."""
        outside = self.calibration.outside
        if not outside or self._warned_calibration:
            return
        self._warned_calibration = True
        what = (f"the replayed receiver {self.source_id!r}" if self.kind == "replay"
                else f"the scripted {self.kind} walker (seed {seed})")
        warnings.warn(warning_text(outside, what), UserWarning, stacklevel=3)

    def feel(self, robot_force: np.ndarray | None, t: float) -> None:
        """This controller tick's robot force on each body segment (S,), N, or None without
        contact: the arm yields to it when ``config.arm_yield``
        (:class:`handover_env.person.arm_yield.ArmYield`)."""
        self.targets.arm.feel(robot_force, t)

    def end_step(self, data: mujoco.MjData) -> None:
        """The env step's physics is done: record the person's effort over it."""
        arm_out = self.state in ("reaching", "presenting", "presented") or (
            self.state == "holding" and not self._released
        )
        # the nominal pelvis at the end of this step
        self.measured.track(data, arm_out, self._pelvis_target, self._dt)

    # ------------------------------------------------------------------ grasp
    def _grasp_xyz(self, centre: list[float],
                   axis: tuple[float, float, float]) -> tuple[float, float, float]:
        """Where the hand holds the object: on its axis, ``grasp_offset`` from its centre
        (``centre + axis * (side * offset)``, one product and one sum per coordinate, on floats:
        numpy's elementwise value of the same expression)."""
        s = self._grasp_side * self.config.grasp_offset
        (ox, oy, oz), (ax, ay, az) = centre, axis
        return ox + ax * s, oy + ay * s, oz + az * s

    @property
    def holding(self) -> bool:
        """True while the person's hand holds the object."""
        return self.grip.active

    def _bind_grasp(self, data: mujoco.MjData) -> None:
        """Views of the grip site's and the object's rows of ``data`` (its buffers never move)."""
        ob = self.ids.object_body
        self._grasp_bound = data
        self._grip_v = data.site_xpos[self.body.grip_site]
        self._object_xpos_v, self._object_xmat_v = data.xpos[ob], data.xmat[ob]

    def try_grasp(self, model: mujoco.MjModel, data: mujoco.MjData) -> bool:
        """Grasp if the grip point is at the object's grasp point and moves with it (within
        ``grasp_radius`` and ``grasp_speed``). Returns True on grasp."""
        if self.state != "reaching":
            return False
        cfg = self.config
        if data is not self._grasp_bound:
            self._bind_grasp(data)
        # |grip - grasp point| on floats (the 3-vector's BLAS dot adds left to right)
        gx, gy, gz = self._grip_v.tolist()
        _, _, ax, _, _, ay, _, _, az = self._object_xmat_v.tolist()
        px, py, pz = self._grasp_xyz(self._object_xpos_v.tolist(), (ax, ay, az))
        dx, dy, dz = gx - px, gy - py, gz - pz
        if math.sqrt(dx * dx + dy * dy + dz * dz) > cfg.grasp_radius:
            return False
        grip = self._grip_v
        v = self._v6
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, self.body.grip_site, v, 0)
        v_grip = v[3:].copy()
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, self.ids.object_body, v, 0)
        if length(v_grip - v[3:]) > cfg.grasp_speed:
            return False
        self.grip.close(data, np.array([0.0, 0.0, self._grasp_side * cfg.grasp_offset]))
        self.state = "holding"
        self.t_grasp = float(data.time)
        self.grasp_pelvis_xy = data.xpos[self.body.bodies[0], :2].copy()
        self.grasp_object_speed = length(v[3:])
        heading = self.base()[2]
        c, s = math.cos(heading), math.sin(heading)
        rx, ry, rz = (self._object_xpos_v - data.xpos[self.body.bodies[0]]).tolist()
        self.grasp_object_body = (rx * c + ry * s, -rx * s + ry * c, rz)
        self.measured.took(data, data.xpos[self.ids.object_body])
        pelvis, rot, _ = self.pose.pelvis(self.tau, self.rho)
        self._hold_rel = (
            rot.T @ (self._hand[0] - pelvis) if self._hand is not None else rot.T @ (grip - pelvis)
        )
        self._hand_goal_time = self.t_grasp + self.config.hold_time + self.config.pull_time
        return True

    # ------------------------------------------------------------------ effort
    def effort(self) -> dict[str, float]:
        """The person's effort so far (see the module docstring)."""
        reach_distance, _, arm_out_time, path_deviation = self.measured.measures()
        return {
            "reach_distance": reach_distance,
            "arm_extended_time": arm_out_time,
            "time_lost": self.time_lost,
            "min_speed_factor": self.min_rho,
            "path_deviation": path_deviation,
        }
