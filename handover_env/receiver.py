"""The MuJoCo side of the receiver: mocap bodies, reach/grasp/pull state machine and replay.

How a person walks and reaches is modelled once, in :mod:`handover_env.receiver_motion` (shared
with the synthetic dataset); this module only drives the scene's two mocap bodies with it:

* ``receiver_base`` (legs, torso, head capsules, sized for the body height) follows the base
  trajectory: a scripted ID/OOD walker from ``receiver_motion.base_trajectory`` or a recorded
  track (replay). Between 30 Hz frames it is interpolated linearly at the 200 Hz control tick.
* ``receiver_hand`` (the right hand) follows a small state machine::

      walking --object within arm's reach--> reaching --hand at object--> holding

  ``walking``: the natural hand swing (``hand_position(..., reach=0)``). ``reaching``: the
  reach fraction rises to 1 in ``reach_time`` s toward the object. ``holding``: the hand grasps
  (the ``receiver_grasp`` weld between hand and object is switched on at the current relative
  pose) and then withdraws toward the carry pose beside the hip at ``pull_speed`` while the body
  keeps walking, so it pulls. The weld is soft (solref 0.06 s) and the robot arm is compliant,
  so the pull is a physical, bounded force that the wrist F/T sensor measures.

  For the static handover (``present_after_walk``) the receiver does not reach while walking; it
  stops at the end of its walk and raises the right hand (``presenting``: forward and to the
  right of the shoulder); the time the hand is fully raised is ``t_hand_raised`` (what a hand
  detector would see). The hand then waits and takes the object only once the robot has brought
  it within ``present_reach`` of the hand.

  ``t_depart`` is when the receiver leaves its start point (first camera frame faster than
  ``depart_speed``): the start of the paper's handover time (Sec. V-C).

Why welds, not finger friction: the grasp on both sides is a weld equality (gripper<->object
while the 2F-85 is closed, hand<->object once the receiver holds it). A friction grasp with the
Menagerie 2F-85 (mesh pads, 5 N actuator) is slow to simulate and brittle under the arm's soft
impedance; what the handover needs is (a) a hold that transmits the pull to the wrist sensor and
(b) a release that really lets go. The gripper weld is switched off only when the fingers have
physically opened past the object (driver angle below ``GRIPPER_OPEN_ANGLE``), so a release
without a receiver grasp lets the object fall: drops remain real outcomes.

The replay receiver takes arrays (base xy (T, 2), optionally hand xyz (T, 3), at 30 Hz) or a
:class:`handover_env.data.dataset.Episode`; by default its hand reaches for the simulated object
like a scripted walker (the recorded hand went to where the *human* giver held the object);
``hand_mode="recorded"`` replays the recorded hand instead and grasps only if it passes within
``grasp_radius`` of the object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from handover_env import receiver_motion as rm
from handover_env.scene import SceneIds, activate_weld

CAMERA_RATE = 30.0


@dataclass(frozen=True)
class ReceiverConfig:
    """Reach/grasp/pull behaviour of the receiver.

    Args:
        reach_margin: the hand starts reaching when the object is within ``arm_reach + margin`` of
            the shoulder (m; negative = only well within reach).
        reach_time: seconds for the reach fraction to go from 0 to 1.
        grasp_radius: the hand grasps when it is this close to the object centre, m.
        pull_speed: speed at which the holding hand withdraws toward the carry pose, m/s.
        carry_forward: the carry pose, m in front of the pelvis (hand beside the hip).
        present_reach: static receiver (``present_after_walk``): it keeps the raised hand still
            and reaches for the object only once the robot has brought it this close to the
            hand, m (the robot delivers to the detected hand, Meng et al. 2022).
        depart_speed: the receiver "leaves the start point" at the first camera frame at which
            its pelvis moves faster than this, m/s (start of the paper's handover time).
    """

    reach_margin: float = 0.0
    reach_time: float = 0.5
    grasp_radius: float = 0.05
    pull_speed: float = 0.4
    carry_forward: float = 0.15
    present_reach: float = 0.15
    depart_speed: float = 0.25

    def __post_init__(self) -> None:
        vals = (self.reach_margin, self.reach_time, self.grasp_radius, self.pull_speed, self.carry_forward,
                self.present_reach, self.depart_speed)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("ReceiverConfig values must be finite")
        if (self.reach_time <= 0 or self.grasp_radius <= 0 or self.pull_speed <= 0 or self.present_reach <= 0
                or self.depart_speed <= 0):
            raise ValueError("reach_time, grasp_radius, pull_speed, present_reach and depart_speed must be > 0")


def _heading_from_track(xy: np.ndarray) -> np.ndarray:
    """Walking direction (yaw) of a recorded base track, smoothed, -x when standing still."""
    vel = np.gradient(xy, axis=0) if len(xy) > 1 else np.zeros_like(xy)
    kernel = np.ones(9) / 9.0
    vel = np.stack([np.convolve(np.pad(vel[:, i], 4, mode="edge"), kernel, "valid") for i in range(2)], axis=1)
    heading = np.empty(len(xy))
    last = math.pi
    for k, (vx, vy) in enumerate(vel):
        if vx * vx + vy * vy > 0.05**2:
            last = math.atan2(vy, vx)
        heading[k] = last
    return np.unwrap(heading)


def _as_array(value: Any, shape1: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != shape1 or arr.shape[0] < 2:
        raise ValueError(f"replay {name} must have shape (T>=2, {shape1}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"replay {name} contains NaN or inf")
    return arr


class Receiver:
    """Drives the receiver mocap bodies and the receiver's grasp.

    Args:
        model: compiled scene.
        ids: scene indices.
        config: reach/grasp/pull behaviour.
    """

    def __init__(self, model: mujoco.MjModel, ids: SceneIds, config: ReceiverConfig | None = None) -> None:
        self.model, self.ids = model, ids
        self.config = config or ReceiverConfig()
        self._geom_defaults = {
            gid: (model.geom_size[gid].copy(), model.geom_pos[gid].copy(), float(model.geom_rbound[gid]))
            for gid in ids.receiver_geoms
        }
        self.kind = "id"
        self.height = 1.75
        self.walker: Any = None
        self.state = "walking"
        self.reach = 0.0
        self.t_grasp = math.nan
        self._frames_xy = np.zeros((2, 2))
        self._frames_heading = np.zeros(2)
        self._frames_hand: np.ndarray | None = None
        self.hand_mode = "reach"
        self.source_id = ""
        self.present_after_walk = False
        self.t_hand_raised = math.nan
        self.t_depart = 0.0
        self._reach_from = None
        self._bound: mujoco.MjData | None = None
        self._xy_list: list[list[float]] = self._frames_xy.tolist()
        self._heading_list: list[float] = self._frames_heading.tolist()
        self._raised_hand: np.ndarray | None = None

    # ------------------------------------------------------------------ setup
    def reset(self, rng: np.random.Generator, kind: str = "id", height: float | None = None,
              speed: float | None = None, episode: Any = None, hand_mode: str = "reach",
              walker_overrides: dict | None = None) -> None:
        """Choose the receiver for a new episode.

        Args:
            rng: the env's ``np_random`` (all randomness comes from it).
            kind: ``"id"`` or ``"ood"`` scripted walker, or ``"replay"``.
            height: body height, m (scripted: overrides the sampled one; replay: default 1.75).
            speed: nominal walking speed, m/s (scripted walkers only).
            episode: for ``"replay"``: an ``Episode`` or a dict with ``receiver_xy`` (T, 2) and
                optionally ``receiver_hand_xyz`` (T, 3), at 30 Hz.
            hand_mode: replay only: ``"reach"`` (model reach) or ``"recorded"``.
            walker_overrides: extra ``WalkerParams`` fields for scripted walkers (e.g. end_x).
        """
        if kind not in ("id", "ood", "replay"):
            raise ValueError(f"receiver must be 'id', 'ood' or 'replay', got {kind!r}")
        if hand_mode not in ("reach", "recorded"):
            raise ValueError(f"hand_mode must be 'reach' or 'recorded', got {hand_mode!r}")
        if height is not None and not (1.2 <= float(height) <= 2.2):
            raise ValueError(f"height must be in [1.2, 2.2] m, got {height}")
        if speed is not None and not (0.1 <= float(speed) <= 2.5):
            raise ValueError(f"speed must be in [0.1, 2.5] m/s, got {speed}")
        self.kind, self.hand_mode = kind, hand_mode if kind == "replay" else "reach"
        self._frames_hand = None
        if kind == "replay":
            if episode is None:
                raise ValueError("receiver='replay' needs options['episode'] (an Episode or a dict of arrays)")
            get = (lambda k: episode.get(k)) if isinstance(episode, dict) else (lambda k: getattr(episode, k, None))
            xy_src = get("receiver_xy")
            if xy_src is None:
                raise ValueError("replay episode needs 'receiver_xy' (T, 2)")
            xy = _as_array(xy_src, 2, "receiver_xy")
            hand = get("receiver_hand_xyz")
            if hand is not None:
                hand = _as_array(hand, 3, "receiver_hand_xyz")
                if hand.shape[0] != xy.shape[0]:
                    raise ValueError(f"replay arrays disagree in length: {xy.shape[0]} vs {hand.shape[0]}")
            if hand_mode == "recorded" and hand is None:
                raise ValueError("hand_mode='recorded' needs 'receiver_hand_xyz' in the episode")
            self._frames_hand = hand if hand_mode == "recorded" else None
            self._frames_xy = xy
            self._frames_heading = _heading_from_track(xy)
            self.height = float(height) if height is not None else 1.75
            self.walker = None
            self.source_id = str(get("source_id") or "replay")
        else:
            overrides = dict(walker_overrides or {})
            if height is not None:
                overrides["height"] = float(height)
            if speed is not None:
                overrides["speed"] = float(speed)
            self.walker = rm.sample_walker(rng, kind, **overrides)
            traj = rm.base_trajectory(self.walker, rate_hz=CAMERA_RATE)
            self._frames_xy = np.asarray(traj.xy, dtype=np.float64)
            self._frames_heading = np.unwrap(np.asarray(traj.heading, dtype=np.float64))
            self.height = float(self.walker.height)
            self.source_id = f"scripted_{kind}"
        self._scale_body(self.height)
        self.t_depart = self._departure_time(self._frames_xy)
        # The hand's rest pose (walking swing) and the shoulder at every camera frame, computed
        # once with the shared motion model (vectorised): env steps end on frame times, so the
        # per-step lookups below give the same values as calling the model at each step.
        self._rest_hand = np.asarray(
            rm.hand_position(self._frames_xy, self._frames_heading, self.height), dtype=np.float64)
        self._shoulder_frames = np.asarray(
            rm.shoulder_position(self._frames_xy, self._frames_heading, self.height), dtype=np.float64)
        self._arm_reach = float(rm.arm_reach(self.height))
        self._xy_list = self._frames_xy.tolist()  # the same frames as floats for per-step lookups
        self._heading_list = self._frames_heading.tolist()
        self.state = "walking"
        self.reach = 0.0
        self.t_grasp = math.nan
        self.t_hand_raised = math.nan
        self._reach_from = None
        self._hand_carry = np.zeros(3)
        self._hand_prev = None
        self._raised_hand = None

    def _departure_time(self, xy: np.ndarray) -> float:
        """When the receiver leaves the start point: first frame whose pelvis speed (central
        difference, 5-frame mean) exceeds ``depart_speed``; 0 for scripted walkers, which walk
        from the first frame; the last frame if the track never moves."""
        speed = np.linalg.norm(np.gradient(xy, axis=0), axis=1) * CAMERA_RATE
        if speed.size >= 5:
            speed = np.convolve(np.pad(speed, 2, mode="edge"), np.ones(5) / 5.0, "valid")
        moving = np.nonzero(speed > self.config.depart_speed)[0]
        k = int(moving[0]) if moving.size else xy.shape[0] - 1
        return k / CAMERA_RATE

    @property
    def duration(self) -> float:
        """Length of the base trajectory, s."""
        return (self._frames_xy.shape[0] - 1) / CAMERA_RATE

    def _scale_body(self, height: float) -> None:
        """Size the legs, torso and head capsules for the body height (defaults are for 1.75 m)."""
        s = height / 1.75
        m = self.model
        for gid, (size, pos, rbound) in self._geom_defaults.items():
            m.geom_size[gid] = size * np.array([s, s, s])
            m.geom_pos[gid] = pos * s
            m.geom_rbound[gid] = rbound * s

    # ------------------------------------------------------------------ queries
    def base_at(self, t: float) -> tuple[np.ndarray, float]:
        """Base xy and heading at time t (linear interpolation; holds the last frame after the end)."""
        x, y, heading = self._base_floats(t)
        return np.array([x, y]), heading

    def _base_floats(self, t: float) -> tuple[float, float, float]:
        """:meth:`base_at` as plain floats (x, y, heading)."""
        n = len(self._xy_list)
        f = min(max(t * CAMERA_RATE, 0.0), n - 1.0)
        i = min(int(f), n - 2)
        a = f - i
        b = 1.0 - a
        (x0, y0), (x1, y1) = self._xy_list[i], self._xy_list[i + 1]
        h0, h1 = self._heading_list[i], self._heading_list[i + 1]
        return x0 * b + x1 * a, y0 * b + y1 * a, h0 * b + h1 * a

    def _at(self, frames: np.ndarray, t: float) -> np.ndarray:
        """Per-frame array ``frames`` (T, k) at time t (linear; holds the last frame)."""
        f = min(max(t * CAMERA_RATE, 0.0), frames.shape[0] - 1.0)
        i = min(int(f), frames.shape[0] - 2)
        a = f - i
        if a < 1e-9:
            return frames[i].copy()
        return frames[i] * (1.0 - a) + frames[i + 1] * a

    def frames_until(self, t: float) -> np.ndarray:
        """All 30 Hz base frames up to time t (what a camera has seen), (n, 2)."""
        n = min(int(math.floor(t * CAMERA_RATE + 1e-9)) + 1, self._frames_xy.shape[0])
        return self._frames_xy[:n]

    def shoulder(self, xy: np.ndarray, heading: float) -> np.ndarray:
        return np.asarray(rm.shoulder_position(xy, heading, self.height), dtype=np.float64)

    # ------------------------------------------------------------------ per env step
    def plan_step(self, t0: float, t1: float, object_pos: np.ndarray, object_free: bool) -> None:
        """Decide the mocap keyframes for the env step [t0, t1] (called once per 30 Hz step).

        Args:
            t0, t1: start and end of the env step, s.
            object_pos: the object's position at t0.
            object_free: whether the object can be reached for (not yet held by the receiver).
        """
        cfg = self.config
        dt = t1 - t0
        bx1, by1, h1 = self._base_floats(t1)
        xy1 = np.array([bx1, by1])
        if self._hand_prev is None:
            xy0, h0 = self.base_at(t0)
            self._hand_prev = self._hand_target(t0, xy0, h0, object_pos, 0.0)
            self._base_prev = (float(xy0[0]), float(xy0[1]), h0)
        if self.present_after_walk and self.state == "walking" and t1 >= self.duration:
            self.state = "presenting"  # static handover: stop and raise the right hand
            self.reach = 0.0
        if self.state == "presenting":
            self.reach = min(1.0, self.reach + dt / cfg.reach_time)
            if self.reach >= 1.0 and math.isnan(self.t_hand_raised):
                self.t_hand_raised = t1
        if object_free and self.hand_mode == "reach":
            if self.state == "walking" and not self.present_after_walk:
                # Walking past: reach as soon as the object is within arm's reach of the shoulder.
                sx, sy, sz = self._at(self._shoulder_frames, t1).tolist()
                ox, oy, oz = object_pos.tolist()
                dx, dy, dz = ox - sx, oy - sy, oz - sz
                if math.sqrt(dx * dx + dy * dy + dz * dz) < self._arm_reach + cfg.reach_margin:
                    self.state = "reaching"
            elif self.state == "presenting" and self.reach >= 1.0:
                # Static: the raised hand waits until the robot brings the object to it.
                if np.linalg.norm(object_pos - self._hand_prev) < cfg.present_reach:
                    self._reach_from = self._hand_prev.copy()
                    self.reach = 0.0
                    self.state = "reaching"
        if self.state == "reaching":
            self.reach = min(1.0, self.reach + dt / cfg.reach_time)
        hand1 = self._hand_target(t1, xy1, h1, object_pos, dt)
        self._hand_next = hand1
        self._base_next = (bx1, by1, h1)

    def _hand_target(self, t: float, xy: np.ndarray, heading: float, object_pos: np.ndarray,
                     dt: float) -> np.ndarray:
        if self.state == "holding":
            # Withdraw toward the carry pose at pull_speed, moving with the body.
            c, s = math.cos(heading), math.sin(heading)
            carry = self._at(self._rest_hand, t)
            carry[:2] += self.config.carry_forward * np.array([c, s])
            rel = self._hand_carry  # hand position relative to the pelvis (world axes)
            goal = carry - np.array([xy[0], xy[1], 0.0])
            step = goal - rel
            dist = float(np.linalg.norm(step))
            if dist > self.config.pull_speed * dt:
                step *= self.config.pull_speed * dt / dist
            self._hand_carry = rel + step
            return np.array([xy[0], xy[1], 0.0]) + self._hand_carry
        if self._frames_hand is not None:
            return self._recorded_hand(xy)
        if self.state == "presenting":
            if self.reach >= 1.0 and self._raised_hand is not None:
                return self._raised_hand.copy()  # standing still with the hand up
            c, s = math.cos(heading), math.sin(heading)
            sh = self.shoulder(xy, heading)
            raised = sh + np.array([0.3 * c + 0.15 * s, 0.3 * s - 0.15 * c, -0.15])  # forward, to the right
            hand = np.asarray(rm.hand_position(xy, heading, self.height, target_xyz=raised, reach=self.reach),
                              dtype=np.float64)
            if self.reach >= 1.0 and t >= self.duration:
                self._raised_hand = hand.copy()
            return hand
        if self.state == "reaching" and self._reach_from is not None:
            goal = self._reach_toward(t, object_pos, 1.0)
            return self._reach_from + self.reach * (goal - self._reach_from)
        if self.reach <= 0.0:
            # Walking: the rest swing (within arm's reach, so the model's reach clip is inactive).
            return self._at(self._rest_hand, t)
        return self._reach_toward(t, object_pos, self.reach)

    def _reach_toward(self, t: float, target: np.ndarray, reach: float) -> np.ndarray:
        """``rm.hand_position(base, heading, height, target_xyz=target, reach=reach)`` at time t.

        Uses that model's rest pose and shoulder precomputed at the camera frames (env steps end
        on frame times) and applies its reach rule: the hand moves the fraction ``reach`` of the
        straight line from the rest pose to the target and is kept within :func:`rm.arm_reach`
        of the shoulder.
        """
        rest = self._at(self._rest_hand, t)
        shoulder = self._at(self._shoulder_frames, t)
        r = min(max(float(reach), 0.0), 1.0)
        offset = rest + r * (target - rest) - shoulder
        ox, oy, oz = offset.tolist()
        dist = math.sqrt(ox * ox + oy * oy + oz * oz)
        if dist > self._arm_reach:
            offset *= self._arm_reach / max(dist, 1e-12)
        return shoulder + offset

    def _recorded_hand(self, xy: np.ndarray) -> np.ndarray:
        assert self._frames_hand is not None
        d = np.linalg.norm(self._frames_xy - xy, axis=1)
        return self._frames_hand[int(np.argmin(d))]

    def _bind(self, data: mujoco.MjData) -> None:
        """Keep views of the ``data`` rows written or read at every tick (MjData buffers never move)."""
        ids = self.ids
        self._bound = data
        self._base_pos_v = data.mocap_pos[ids.base_mocap]
        self._base_quat_v = data.mocap_quat[ids.base_mocap]
        self._hand_pos_v = data.mocap_pos[ids.hand_mocap]
        self._object_pos_v = data.xpos[ids.object_body]

    def apply(self, data: mujoco.MjData, alpha: float) -> None:
        """Move the mocap bodies to the fraction ``alpha`` in [0, 1] of the current env step."""
        self._set_mocap(data, alpha)
        self._base_quat_v[1] = self._base_quat_v[2] = 0.0

    def plan_ticks(self, alphas: np.ndarray | list[float]) -> None:
        """Set the fractions ``alphas`` of this env step at which the ticks fall (kept, not copied,
        if given as a list of floats)."""
        self._tick_alphas = alphas if isinstance(alphas, list) else np.asarray(alphas, dtype=np.float64).tolist()
        self._tick_i = 0

    def apply_tick(self, data: mujoco.MjData) -> None:
        """Move the mocap bodies to their pose at the next tick (linear between the keyframes)."""
        a = self._tick_alphas[self._tick_i]
        self._tick_i += 1
        self._set_mocap(data, a)

    def _set_mocap(self, data: mujoco.MjData, a: float) -> None:
        """Base xy and yaw and hand xyz at the fraction ``a`` between the keyframes (plain floats)."""
        if data is not self._bound:
            self._bind(data)
        bx0, by0, bh0 = self._base_prev
        bx1, by1, bh1 = self._base_next
        yaw = bh0 + a * (bh1 - bh0)
        bp = self._base_pos_v
        bp[0] = bx0 + a * (bx1 - bx0)
        bp[1] = by0 + a * (by1 - by0)
        bq = self._base_quat_v
        bq[0], bq[3] = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
        hx0, hy0, hz0 = self._hand_prev.tolist()
        hx1, hy1, hz1 = self._hand_next.tolist()
        hp = self._hand_pos_v
        hp[0] = hx0 + a * (hx1 - hx0)
        hp[1] = hy0 + a * (hy1 - hy0)
        hp[2] = hz0 + a * (hz1 - hz0)

    def end_step(self) -> None:
        """The env step is over: its end keyframes become the next step's start."""
        self._hand_prev = self._hand_next
        self._base_prev = self._base_next

    def try_grasp(self, model: mujoco.MjModel, data: mujoco.MjData) -> bool:
        """Grasp if the hand is at the object (switches the receiver weld on). Returns True on grasp."""
        if self.state == "holding":
            return False
        if self.hand_mode == "reach" and self.state != "reaching":
            return False
        if data is not self._bound:
            self._bind(data)
        hx, hy, hz = self._hand_pos_v.tolist()
        ox, oy, oz = self._object_pos_v.tolist()
        dx, dy, dz = hx - ox, hy - oy, hz - oz
        if math.sqrt(dx * dx + dy * dy + dz * dz) > self.config.grasp_radius:
            return False
        hand = self._hand_pos_v
        activate_weld(model, data, self.ids.eq_receiver, torquescale=0.2, zero_force=True)
        self.state = "holding"
        self.t_grasp = float(data.time)
        base = data.mocap_pos[self.ids.base_mocap]
        self._hand_carry = hand - np.array([base[0], base[1], 0.0])
        self._hand_next = hand.copy()  # hold still for the rest of this env step
        self._hand_prev = hand.copy()
        return True

    def place(self, data: mujoco.MjData, t: float, object_pos: np.ndarray) -> None:
        """Put the mocap bodies at their pose for time t (used at reset)."""
        self._hand_prev = None
        self.plan_step(t, t, object_pos, True)
        self.plan_ticks(np.zeros(1))
        self.apply_tick(data)
