"""Shared core of the handover envs: physics loop, wrist F/T, release, outcomes, observation.

The two registered envs (:mod:`.dynamic_handover_v0`, :mod:`.static_handover_v0`) differ only in
their task (:mod:`handover_env.envs.tasks`): the receiver's set-up (walking past vs. stopping and
raising a hand), when the robot may move, when an episode ends, and the reward. Everything below
is common; a task is a constructor argument (``task=``), so a new variant is one task file.

Timing: physics dt = 1/600 s; the impedance controller runs every 3 physics steps (200 Hz) on a
global step counter, so its rate holds across env steps; one env step = 1/30 s = 20 physics steps
(6 or 7 controller ticks). The receiver's mocap bodies are moved at every tick.

Wrist force: the external wrench at the wrist F/T sensor, static load removed and low-pass
filtered at every tick (:mod:`handover_env.envs.wrist`). When its magnitude exceeds f_r the
gripper opens (paper Sec. IV-C).

This module is over 500 lines because the env's physics loop is one class: reset, step, the
200 Hz tick, the observation and the info all work on the same views of ``MjData`` bound once
(``_bind_data``) for the hot loop. What stands on its own is in its own module: the tasks
(:mod:`handover_env.envs.tasks`), the wrist sensor (:mod:`.wrist`), the body contacts
(:mod:`.contacts`) and the observation layout (:mod:`.observation`).

Outcomes (``info["outcome"]``), all with ``terminated=True`` except "running":

* ``success``: the robot released the object while the receiver held it, the fingers have let go
  (gripper weld off) and the receiver has taken the object clear of the gripper (object centre
  more than ``CLEAR_DISTANCE`` = 6 cm from the TCP) while still holding it.
* ``premature_release``: the gripper opened (the wrist force exceeded f_r) before the person's
  hand held the object, e.g. when the body bumped into the bottle. Never a success, even if the
  hand catches the object afterwards: the episode ends at the release.
* ``dropped``: nobody holds the object (gripper weld off, receiver not holding) and it has fallen
  0.15 m below where it was last held, or touches the floor.
* ``unsafe_force``: the person's pull on an object the robot still holds (the grip force,
  :mod:`handover_env.person.grip`) exceeded ``safety_force`` (default 140 N: ISO/TS 15066, Annex A,
  maximum permissible quasi-static force for the hand and fingers: a tug of war), or a
  robot/object contact on a body segment exceeded its body region's ISO/TS 15066 limit
  (:mod:`handover_env.envs.contacts`). The wrist sensor's peak is reported but not held to a
  limit: after the release it measures contacts, which are judged where they touch the body.
* ``unstable``: MuJoCo reported a diverging position, velocity or acceleration (and reset its
  state); the episode is void and says so instead of going on from a reset simulation.
* ``missed``: the person walked past without taking the object (gave up on an object left
  behind them, see :class:`handover_env.person.settings.ReceiverConfig`), or their walk ended (+1 s)
  without it. The static receiver waits; there only the TimeLimit ends an episode.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle

from handover_env.envs import observe as ob
from handover_env.envs.config import EnvConfig
from handover_env.envs.contacts import ContactMonitor
from handover_env.envs.tasks.base import TERMS, HandoverReward, HandoverTask
from handover_env.envs.tasks.dynamic import DynamicHandover
from handover_env.envs.wrist import WristSensor
from handover_env.mjdata_view import MjDataView
from handover_env.person.motion import check_overrides
from handover_env.person.receiver import CAMERA_RATE, Receiver
from handover_env.robot.controller import ControllerConfig, ImpedanceController, inverse_kinematics
from handover_env.robot.scene import build_model, place_object_in_gripper, scene_ids
from handover_env.sensors import Camera, SensorProfile, make_profile
from handover_env.sensors.profiles import profile_summary

CLEAR_DISTANCE = 0.06  # m, object centre to TCP: the 6.6 cm bottle is out from between the pads
FRAME_SKIP = 20  # physics steps per env step (1/30 s at dt = 1/600 s)
GRIPPER_CLOSED_CTRL = 90.0  # 2F-85 command at which the pads meet the 66 mm bottle
GRIPPER_OPEN_CTRL = 0.0
GRIPPER_OPEN_ANGLE = 0.2  # driver angle (rad) below which the pads have left the bottle
READY_POS = np.array([0.3, -0.4, 1.15])
READY_YAW = -math.pi / 2
HOME_Q = np.array([-2.3, -1.8, 2.1, -0.3, -3.9, 0.0])
ACTION_LOW = np.array([-0.3, -1.1, 0.8, -math.pi], dtype=np.float32)
ACTION_HIGH = np.array([0.9, 0.1, 1.6, math.pi], dtype=np.float32)
OUTCOMES = (
    "running",
    "success",
    "premature_release",
    "dropped",
    "unsafe_force",
    "missed",
    "unstable",
)
#: MuJoCo's warnings for a diverging state (it then resets the simulation).
_DIVERGED = tuple(
    int(w)
    for w in (
        mujoco.mjtWarning.mjWARN_BADQPOS,
        mujoco.mjtWarning.mjWARN_BADQVEL,
        mujoco.mjtWarning.mjWARN_BADQACC,
    )
)
#: info keys of the reward terms a task reports (``reward_<term>``)
_REWARD_KEYS = {term: f"reward_{term}" for term in TERMS}
#: reset() options the envs understand; anything else is warned about by name.
RESET_OPTIONS = ("receiver", "episode", "height", "speed", "hand_mode", "walker")


class HandoverEnvBase(gym.Env, EzPickle):
    """Common implementation; use ``DynamicHandoverEnv`` or ``StaticHandoverEnv``.

    Built from an :class:`~handover_env.envs.config.EnvConfig`: ``config=``, or its fields as
    keywords (what ``gym.make`` passes). Θ is ``params=`` (a
    :class:`~handover_env.config.HandoverParams` or a dict of its fields); ``gym.make`` users
    may give its four fields as the loose keywords ``stiffness``, ``damping``,
    ``forecast_time`` and ``release_force`` instead (not both). ``task`` (a
    :class:`~handover_env.envs.tasks.base.HandoverTask`) replaces the env's own
    (:meth:`default_task`); ``reward`` (a :class:`~handover_env.envs.tasks.base.HandoverReward`
    or a dict of its fields) sets the default task's reward weights.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 30}

    def __init__(
        self, render_mode: str | None = None, config: EnvConfig | None = None, **keywords: Any
    ) -> None:
        EzPickle.__init__(self, render_mode, config, **keywords)
        self._check_render_mode(render_mode)
        self.config = cfg = EnvConfig.of(config, **keywords)
        self.sensing, self.sensor_overrides = cfg.sensing, cfg.sensor_overrides
        # "paper" and "ideal" are fixed; "randomized" is drawn at each reset.
        self.sensor_profile: SensorProfile = cfg.sensor_profile()
        self.params = cfg.params
        self.stabilisation_delay = cfg.stabilisation_delay
        self.render_mode = render_mode
        self.safety_force, self.miss_distance = cfg.safety_force, cfg.miss_distance
        self.default_receiver = cfg.default_receiver
        self.clear_distance = CLEAR_DISTANCE
        self.width, self.height, self.camera = cfg.width, cfg.height, cfg.camera
        self.task = cfg.task if cfg.task is not None else self.default_task(
            cfg.reward or HandoverReward()
        )
        self.model = build_model(cfg.scene)
        self.data = mujoco.MjData(self.model)
        self.ids = scene_ids(self.model)
        self.layout = cfg.layout
        self.controller = ImpedanceController(
            self.model, self.ids, self.params, ControllerConfig(ticks=self._controller_ticks())
        )
        self.receiver = Receiver(self.model, self.ids.receiver, cfg.receiver)
        self.dt = self.model.opt.timestep * FRAME_SKIP
        self._ticks = self.controller.config.ticks
        self._schedule_ticks()
        self.data_view = MjDataView(self.data)
        self.wrist = WristSensor(
            self.model, self.data, self.ids, self._ticks, self.sensor_profile.wrist.filter_tau,
            self.data_view,
        )
        self._make_spaces()
        self.contacts = ContactMonitor(
            self.model, self.ids, tick=self.model.opt.timestep * self._ticks
        )
        self._bind_data()
        self._init_state, self._ready_q = self._settled_start()
        self._renderer: Any = None
        self._viewer: Any = None
        self._global_step = 0
        self._reset_episode_state()

    def _check_render_mode(self, render_mode: str | None) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, got "
                f"{render_mode!r}"
            )
        if (
            render_mode == "human"
            and not os.environ.get("DISPLAY")
            and not os.environ.get("WAYLAND_DISPLAY")
        ):
            raise RuntimeError(
                "render_mode='human' needs a display (DISPLAY is not set); use "
                "render_mode='rgb_array' (with MUJOCO_GL=egl or osmesa) on a headless machine"
            )

    def _controller_ticks(self) -> int:
        """Physics steps per controller tick (the profile's rate must divide the physics')."""
        ctrl_rate, dt_phys = self.sensor_profile.controller.control_rate_hz, self.model.opt.timestep
        ticks = round(1.0 / (dt_phys * ctrl_rate))
        if ticks < 1 or abs(ticks * dt_phys * ctrl_rate - 1.0) > 1e-9:
            raise ValueError(
                f"controller control_rate_hz must divide the {1 / dt_phys:g} Hz physics rate "
                f"(600, 300, 200, 150, 120, 100, ... Hz), got {ctrl_rate:g}"
            )
        return ticks

    def _schedule_ticks(self) -> None:
        """Where the controller ticks fall in an env step, by the global step's phase."""
        # Fractions of an env step at which ticks fall, by the global step phase at its start.
        self._tick_alphas = [
            [k / FRAME_SKIP for k in range(FRAME_SKIP) if (phase + k) % self._ticks == 0]
            for phase in range(self._ticks)
        ]
        # Per phase: (tick at the segment start?, physics steps until the next tick or step end).
        self._segments = []
        for phase in range(self._ticks):
            starts = [k for k in range(FRAME_SKIP) if (phase + k) % self._ticks == 0]
            bounds = sorted(set([0, *starts, FRAME_SKIP]))
            self._segments.append(
                [(lo in starts, hi - lo) for lo, hi in zip(bounds[:-1], bounds[1:])]
            )

    def _make_spaces(self) -> None:
        """The observation and action Boxes, and the buffers the observation is built in."""
        low, high = self.layout.bounds()
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.action_space = spaces.Box(ACTION_LOW.copy(), ACTION_HIGH.copy(), dtype=np.float32)
        self._obs_low, self._obs_high = low, high
        self._slices = {k: v[0] for k, v in self.layout.slices().items()}
        self._obs = np.zeros(self.layout.size, dtype=np.float64)
        self._act_low, self._act_high = (
            ACTION_LOW.astype(np.float64).tolist(),
            ACTION_HIGH.astype(np.float64).tolist(),
        )
        self._obs_bounds = np.vstack([low, high]).astype(np.float64)
        self._obs_pv = np.zeros(ob.PV_SIZE)
        self._vel6 = np.zeros(6)
        self._obj_linvel_v = self._vel6[3:]  # the object's linear velocity (mj_objectVelocity)

    def default_task(self, reward: HandoverReward) -> HandoverTask:
        """The task of this env when none is given (the dynamic handover here)."""
        return DynamicHandover(reward=reward)

    def _bind_data(self) -> None:
        """Views of the ``self.data`` rows read or written at every tick or step.

        ``self.data`` lives as long as the env and MjData buffers never move, so the views stay
        valid; they save the attribute lookups and index arithmetic in the hot loop.
        """
        d, ids = self.data, self.ids
        m, view, sl = self.model, self.data_view, self._slices
        oi = self._obs_oi = np.zeros(ob.OI_SIZE, dtype=np.int64)
        for slot, name in ((ob.O_HIST, "receiver_xy_history"), (ob.O_SEEN, "receiver_frames_seen"),
                           (ob.O_EEPOS, "ee_pos"), (ob.O_QUAT, "ee_quat"),
                           (ob.O_LIN, "ee_linvel"), (ob.O_ANG, "ee_angvel"),
                           (ob.O_OBJ, "object_pos"), (ob.O_HELD, "object_held"),
                           (ob.O_FORCE, "wrist_force"), (ob.O_TORQUE, "wrist_torque"),
                           (ob.O_OPEN, "gripper_open"), (ob.O_TIME, "time"),
                           (ob.O_HAND, "receiver_hand_xyz"), (ob.O_ENABLED, "robot_enabled")):
            oi[slot] = sl[name].start
        oi[ob.O_W] = self.layout.history
        tcp_body = int(m.site_bodyid[ids.tcp_site])
        oi[ob.M_TCP_POS] = view.offset("site_xpos", ids.tcp_site)
        oi[ob.M_TCP_MAT] = view.offset("site_xmat", ids.tcp_site)
        oi[ob.M_TCP_CVEL] = view.offset("cvel", tcp_body)
        oi[ob.M_TCP_COM] = view.offset("subtree_com", int(m.body_rootid[tcp_body]))
        oi[ob.M_OBJ_POS] = view.offset("xpos", ids.object_body)
        self._gripper_qpos = ids.gripper_driver_qpos
        self._object_body = ids.object_body
        self._qpos_v = d.qpos
        self._eq_active_v = d.eq_active
        self._object_pos_v = d.xpos[ids.object_body]
        self._tcp_pos_v = d.site_xpos[ids.tcp_site]
        self._tcp_xmat_v = d.site_xmat[ids.tcp_site]
        self._grip_v = d.site_xpos[ids.body.grip_site]
        self._object_xmat_v = d.xmat[ids.object_body]
        self._object_rot_v = self._object_xmat_v.reshape(3, 3)
        self._tcp_axis_v = self._tcp_xmat_v.reshape(3, 3)[:, 2]  # the gripper's approach axis
        # MuJoCo's warning counters of a diverging state (the binding's objects view MjData)
        self._diverged = tuple(d.warning[w] for w in _DIVERGED)

    # ------------------------------------------------------------------ start state
    def _settled_start(self) -> tuple[np.ndarray, np.ndarray]:
        """The robot at the ready pose holding the object, settled for 0.5 s (computed once)."""
        m, d, ids = self.model, self.data, self.ids
        mujoco.mj_resetData(m, d)
        q = inverse_kinematics(m, mujoco.MjData(m), ids, READY_POS, READY_YAW, HOME_Q)
        d.qpos[ids.arm_qpos] = q
        # Close the fingers to the bottle width before placing the object.
        d.ctrl[ids.gripper_act] = GRIPPER_CLOSED_CTRL
        mujoco.mj_forward(m, d)
        place_object_in_gripper(m, d, ids)
        ctrl = ImpedanceController(m, ids, self.params, ControllerConfig(), rest_qpos=q)
        ctrl.payload_mass = float(m.body_mass[ids.object_body])
        mujoco.mj_forward(m, d)
        ctrl.reset(d)
        ctrl.set_target(READY_POS, READY_YAW)
        # The person stands at the model's parking spot, well away, while the arm settles.
        for _ in range(100):
            ctrl.compute(d)  # writes the arm's torques to d.ctrl
            mujoco.mj_step(m, d, nstep=ctrl.config.ticks)
        d.time = 0.0
        state = np.empty(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(m, d, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        self._gripper_eq_data = m.eq_data[ids.eq_gripper].copy()
        return state, q

    def _reset_episode_state(self) -> None:
        self.outcome = "running"
        self.released = False
        self.t_release = math.nan
        self.release_force = math.nan
        self.peak_contact_force = 0.0
        self.peak_wrist_force = 0.0
        self.pull_force = 0.0
        self.released_while_held = False
        self.transfer_object_pos: np.ndarray | None = None
        self.transfer_robot_jerk = math.nan
        self.wrist.reset()
        self._gripper_holds = True
        self._last_held_z = float(READY_POS[2])
        self.t_enabled = 0.0
        self.t_detect = math.nan
        # the camera's delivered pelvis frames (rows [0, _n_hist)), oldest first, and how many
        # it has delivered (0 until the first frame is available: _n_hist is then 1, the
        # earliest capture, as the camera reports it)
        self._frames_buf = np.zeros((1024, 2))
        self._n_hist = 0
        self._frames_seen = 0
        self._n_captured = 0
        self._hand_obs: list[float] = [0.0, 0.0, 0.0]
        self._pending: list[tuple[float, tuple[float, float, float], float]] = []
        self._step_count = 0
        self.contacts.reset()
        self._tcp_hist: list[list[float]] = []
        self._jerk_sq = 0.0
        self._jerk_peak_sq = 0.0
        self._jerk_n = 0
        self._jerk_now = math.nan
        self.reward_terms = dict.fromkeys(TERMS, 0.0)

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._ready = False  # a reset that fails leaves an env that must be reset again
        super().reset(seed=seed)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"reset options must be a dict, got {type(options).__name__}")
        options = dict(options or {})
        if options.get("walker") is not None:
            # Field by field, before a task merges in its own (the static stop line).
            options["walker"] = check_overrides(options["walker"])
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            gym.logger.warn(
                f"reset() ignores unknown option(s) {unknown}; known: {list(RESET_OPTIONS)}"
            )
        kind = options.get("receiver", self.default_receiver)
        m, d, ids = self.model, self.data, self.ids
        # The person is chosen (and every option validated) before any state changes.
        self.task.configure_receiver(self, kind, options)
        self.receiver.warn_outside(seed)  # once per env: a walk outside the calibrated range
        mujoco.mj_resetData(m, d)
        mujoco.mj_setConst(m, d)  # the person's masses and sizes changed (uses d as scratch)
        mujoco.mj_setState(m, d, self._init_state, mujoco.mjtState.mjSTATE_INTEGRATION)
        m.eq_data[ids.eq_gripper] = self._gripper_eq_data
        d.eq_active[ids.eq_gripper] = 1
        d.ctrl[ids.gripper_act] = GRIPPER_CLOSED_CTRL
        self._reset_episode_state()
        self._global_step = 0  # the controller's tick clock restarts with the episode
        self.receiver.start(d)
        mujoco.mj_forward(m, d)
        self._last_held_z = float(d.xpos[ids.object_body, 2])
        self.controller.reset(d, rest_qpos=self._ready_q)
        self.controller.payload_mass = float(m.body_mass[ids.object_body])
        self.wrist.update_payload(self._gripper_holds)
        self._start_sensors()
        self._record_camera_frame()
        self._tcp_hist.append(self._tcp_pos_v.tolist())
        self.t_enabled = self.task.enabled_time(self)
        self._ready = True
        if self.render_mode == "human":
            self.render()
        info = self._info()
        info["sensing_params"] = profile_summary(self.sensor_profile)
        return self._observation(), info

    def _sensor_rng(self) -> np.random.Generator:
        """The episode's sensor Generator: a child of ``np_random`` (``Generator.spawn``), so the
        sensors draw nothing from the person's stream and a seed fixes both."""
        try:
            return self.np_random.spawn(1)[0]
        except (TypeError, AttributeError, ValueError):  # a generator without a SeedSequence
            return np.random.default_rng(int(self.np_random.integers(2**63)))

    def _start_sensors(self) -> None:
        """The episode's sensor profile (drawn for "randomized"), camera, wrist model and
        controller settings (docs/sensing.md); the wrist is zeroed here, the arm settled at the
        ready pose holding the object, as a UR program would before moving toward the person."""
        rng = self._sensor_rng()
        if self.sensing == "randomized":
            self.sensor_profile = make_profile("randomized", self.sensor_overrides, rng=rng)
        prof = self.sensor_profile
        c = prof.controller
        default_speed = ControllerConfig().max_linear_speed
        self.controller.set_limits(
            inertia=c.inertia, joint_speed_limit=c.joint_speed_limit,
            joint_accel_limit=c.joint_accel_limit,
            max_linear_speed=min(default_speed, c.tcp_speed_limit) if c.tcp_speed_limit > 0
            else default_speed,
        )
        self._cmd_delay = c.command_delay
        self._pending.clear()
        self.camera_model = Camera(prof.camera).reset(rng)
        self._camera_delay = self.camera_model.delay_frames
        self.wrist.start(prof.wrist, rng)

    def _record_camera_frame(self) -> None:
        """One 30 Hz camera frame of the person: pelvis xy and right hand (the grip site)."""
        hx, hy, hz, px, py, _ = self.camera_model.capture(
            float(self.data.time), self._grip_v, self.receiver.camera_xy()
        )
        self._n_captured += 1
        buf = self._frames_buf
        if self._n_captured <= self._camera_delay:  # nothing delivered yet: the first capture
            k = 0
            self._n_hist = 1
        else:
            k = self._frames_seen
            if k >= buf.shape[0]:  # an env stepped past its TimeLimit (or without one)
                buf = self._frames_buf = np.concatenate([buf, np.zeros_like(buf)])
            self._frames_seen = self._n_hist = k + 1
        buf[k, 0], buf[k, 1] = px, py
        self._hand_obs = [hx, hy, hz]

    def step(self, action: np.ndarray):
        if not getattr(self, "_ready", False):
            raise RuntimeError(
                "step() called before reset() (a copied or unpickled env is a fresh, "
                "un-reset env); call reset() first"
            )
        if self.outcome != "running":
            raise RuntimeError("step() called after the episode ended; call reset()")
        a = np.asarray(action)
        kind = a.dtype.kind  # "f" floating, "i"/"u" integer: np.issubdtype without its cost
        if a.shape != (4,) or kind not in "fiu":
            raise ValueError(f"action must be 4 finite real numbers (x, y, z, yaw), got {action!r}")
        # float16/32/64 become the same Python floats as through float64; others convert first
        vals = (a if kind == "f" and a.dtype.itemsize <= 8 else a.astype(np.float64)).tolist()
        x, y, z, yaw = vals
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and math.isfinite(yaw)):
            raise ValueError(f"action must be 4 finite numbers (x, y, z, yaw), got {action!r}")
        lo, hi = self._act_low, self._act_high  # np.clip to the Box
        x, y, z = min(max(x, lo[0]), hi[0]), min(max(y, lo[1]), hi[1]), min(max(z, lo[2]), hi[2])
        yaw = min(max(yaw, lo[3]), hi[3])
        m, d = self.model, self.data
        t0 = d.time
        if t0 < self.t_enabled:
            x, y, z = READY_POS.tolist()
            yaw = READY_YAW
        if self._cmd_delay > 0.0:  # the command reaches the controller command_delay later
            self._pending.append((t0 + self._cmd_delay - 1e-9, (x, y, z), yaw))
        elif t0 >= self.t_enabled:
            self.controller.set_target((x, y, z), yaw)
        else:
            self.controller.set_target(READY_POS, READY_YAW)
        t1 = t0 + self.dt
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, self._object_body, self._vel6, 0)
        # views, not copies: plan_step only reads them, before any physics moves them
        self.receiver.plan_step(t0, t1, d, self._object_pos_v, self._obj_linvel_v,
                                self._object_rot_v, not self._receiver_holds, self.released,
                                self._tcp_pos_v,
                                self._tcp_axis_v if self._gripper_holds else None)
        self.receiver.targets.plan_ticks(self._tick_alphas[self._global_step % self._ticks])

        # The controller ticks on the global step clock: the schedule of (tick?, physics steps)
        # segments depends only on the clock's phase at the start of the env step.
        apply_tick, tick = self.receiver.targets.apply_tick, self._tick
        mj_step = mujoco.mj_step
        contacts = self.contacts
        pending = self._pending
        for is_tick, n in self._segments[self._global_step % self._ticks]:
            if is_tick:
                apply_tick(d)
                if pending and pending[0][0] <= d.time:
                    self._apply_command()
                tick()
                if contacts.unsafe_segment >= 0:
                    # the episode ends at the unsafe contact, not pressed on to the step's end
                    break
            mj_step(m, d, n)  # positional arguments: the binding parses keywords per call
        self._global_step += FRAME_SKIP
        self.receiver.targets.apply(d, 1.0)
        self.receiver.end_step(d)
        self._step_count += 1
        self._record_camera_frame()
        self._track_jerk()
        self._after_step()
        self.reward_terms = self.task.reward_terms(self)
        reward = 0.0
        for term in self.reward_terms.values():
            reward += term
        terminated = self.outcome != "running"
        if self.render_mode == "human":
            self.render()
        return self._observation(), reward, terminated, False, self._info()

    # ------------------------------------------------------------------ internals
    def _apply_command(self) -> None:
        """Hand the controller the newest command that has arrived by now (command_delay)."""
        pending, t = self._pending, self.data.time
        k = 0
        while k < len(pending) and pending[k][0] <= t:
            k += 1
        _, pos, yaw = pending[k - 1]
        del pending[:k]
        self.controller.set_target(pos, yaw)

    @property
    def _receiver_holds(self) -> bool:
        return self.receiver.grip.active

    # what a task reads of the env's state
    @property
    def receiver_holds(self) -> bool:
        """The person's hand holds the object."""
        return self.receiver.grip.active

    @property
    def gripper_holds(self) -> bool:
        """The gripper holds the object (its weld is on)."""
        return self._gripper_holds

    @property
    def last_held_z(self) -> float:
        """Height (m) of the object when it was last held by anyone."""
        return self._last_held_z

    def object_position(self) -> np.ndarray:
        """The object's position (a view: copy it to keep it)."""
        return self._object_pos_v

    def wrist_force_magnitude(self) -> float:
        """N, the measured wrist force's magnitude (what the release compares with f_r)."""
        return self.wrist.magnitude()

    @property
    def f_ext(self) -> np.ndarray:
        """(3,) N, the measured external wrist force (world frame): the wrist F/T model's reading
        (:mod:`handover_env.envs.wrist`); the exact one is ``wrist.f_true``."""
        return self.wrist.f_ext

    def clear_of_gripper(self, ox: float, oy: float, oz: float) -> bool:
        """Whether the object centre is more than ``clear_distance`` from the TCP."""
        px, py, pz = self._tcp_pos_v.tolist()
        dx, dy, dz = ox - px, oy - py, oz - pz
        return math.sqrt(dx * dx + dy * dy + dz * dz) > self.clear_distance

    def _tick(self) -> None:
        """One 200 Hz controller tick: F/T estimate, release, grasps, contacts, torques.

        The wrist sensor (:func:`handover_env.envs.wrist_tick.wrist_tick`) and the controller
        (:func:`handover_env.robot.impedance_tick.impedance_tick`) are one compiled call each;
        what stays here is the tick's decisions, each a comparison on floats.
        """
        d = self.data
        f_mag = self.wrist.tick()
        if f_mag > self.peak_wrist_force:
            self.peak_wrist_force = f_mag
        rec = self.receiver
        grip = rec.grip
        holds = grip.active
        if holds and self._gripper_holds:
            pull = grip.force  # what the person pulls with while both hold the object
            p = math.sqrt(float(pull[0] * pull[0] + pull[1] * pull[1] + pull[2] * pull[2]))
            if p > self.pull_force:
                self.pull_force = p
        if not self.released and f_mag > self.params.release_force:
            self.released = True
            self.released_while_held = bool(holds)
            self.t_release = float(d.time)
            self.release_force = f_mag
            d.ctrl[self.ids.gripper_act] = GRIPPER_OPEN_CTRL
        if (
            self.released
            and self._gripper_holds
            and self._qpos_v[self._gripper_qpos] < GRIPPER_OPEN_ANGLE
        ):
            d.eq_active[self.ids.eq_gripper] = 0
            self._gripper_holds = False
            self.controller.payload_mass = 0.0
            self.wrist.update_payload(self._gripper_holds)
        if rec.state == "reaching" and rec.try_grasp(self.model, d):
            self.transfer_object_pos = self._object_pos_v.copy()
            self.transfer_robot_jerk = self._jerk_now
        if grip.active:
            grip.apply(d)
        contacts = self.contacts
        contacts.count_object = self._gripper_holds or not grip.active
        if contacts.active or d.ncon:
            contacts.scan(d)
            rec.feel(contacts.robot_now, float(d.time))
        elif rec.targets.arm.touching:
            rec.feel(None, float(d.time))
        if self._gripper_holds or grip.active:
            self._last_held_z = float(self._object_pos_v[2])
        self.controller.compute(d)  # writes the arm's torques to d.ctrl

    def _track_jerk(self) -> None:
        """Robot TCP jerk from the third difference of its 30 Hz positions (RMS, peak, and the
        last step's, which the grasp records as ``transfer_robot_jerk``)."""
        hist = self._tcp_hist
        hist.append(self._tcp_pos_v.tolist())
        if len(hist) < 4:
            return
        r = CAMERA_RATE**3
        (a0, a1, a2), (b0, b1, b2), (c0, c1, c2), (e0, e1, e2) = (
            hist[3], hist[2], hist[1], hist[0]
        )
        j2 = (((a0 - 3.0 * b0 + 3.0 * c0 - e0) * r) ** 2
              + ((a1 - 3.0 * b1 + 3.0 * c1 - e1) * r) ** 2
              + ((a2 - 3.0 * b2 + 3.0 * c2 - e2) * r) ** 2)
        self._jerk_sq += j2
        self._jerk_now = math.sqrt(j2)
        self._jerk_n += 1
        if j2 > self._jerk_peak_sq:
            self._jerk_peak_sq = j2
        del hist[0]

    def _after_step(self) -> None:
        if math.isinf(self.t_enabled):  # the task tells when the robot may move, once it knows
            self.t_detect = self.task.detection_time(self)
            self.t_enabled = self.task.enabled_time(self)
        bad_qpos, bad_qvel, bad_qacc = self._diverged
        if bad_qpos.number or bad_qvel.number or bad_qacc.number:
            # MuJoCo found a diverging acceleration and reset the simulation: the episode is void.
            self.outcome = "unstable"
            return
        self.peak_contact_force = max(self.peak_wrist_force, self.contacts.peak_max)
        self.outcome = self.task.outcome(self)

    def _observation(self) -> np.ndarray:
        """The observation (:func:`handover_env.envs.observe.observe`, one compiled call)."""
        pv = self._obs_pv
        t = self.data.time
        pv[ob.V_NHIST] = self._n_hist
        pv[ob.V_SEEN] = self._frames_seen
        pv[ob.V_HELD] = 1.0 if self._gripper_holds else 0.0
        pv[ob.V_OPEN] = 1.0 if self.released else 0.0
        pv[ob.V_TIME] = t
        pv[ob.V_ENABLED] = 1.0 if t >= self.t_enabled else 0.0
        pv[ob.V_HAND:ob.V_HAND + 3] = self._hand_obs
        return ob.observe(self.data_view.mem, self._obs, self._obs_bounds, self._obs_oi, pv,
                          self._frames_buf, self.wrist.state)

    def _info(self) -> dict[str, Any]:
        """Episode facts; values not yet defined (no release, no grasp) are ``None``.

        Besides the outcome and the paper's handover time: when and where the object changed
        hands (``transfer_time``: the person's grasp; ``transfer_pelvis_xy``,
        ``transfer_object_pos``; the presentation: ``transfer_object_body``, the bottle in the
        person's walking frame, ``transfer_object_speed`` and ``transfer_robot_jerk``),
        whether the person walks within the calibrated range (``within_calibration``) and their
        own reach offset (``reach_offset``, m; 0 unless the person setting is on), the person's
        effort (``reach_distance``, ``arm_extended_time``, ``time_lost``,
        ``min_speed_factor``, ``path_deviation``, ``pull_force``) and contact with the body
        (``contact_force_<segment>``, ``body_contact_force``, ``penetration``,
        ``body_contact_robot``, ``body_contact_object``).
        """
        outcome = self.outcome
        ok = outcome == "success"
        rec = self.receiver
        # Paper Sec. V-C: from when the receiver leaves the start point to the gripper release;
        # the static baseline's stabilisation delay is subtracted ("handover_time") or not.
        t_depart = rec.t_depart
        t_ho = self.t_release - t_depart
        f_rel, t_rel = self.release_force, self.t_release
        t_grasp, t_reach = rec.t_grasp, rec.t_reach
        # (x != x: x is NaN, math.isnan without its call)
        info: dict[str, Any] = {
            "is_success": ok,
            "outcome": outcome,
            "handover_time": (t_ho - self.task.handover_delay) if ok else None,
            "handover_time_with_delay": t_ho if ok else None,
            "release_force": None if f_rel != f_rel else f_rel,
            "released": self.released,
            "release_time": None if t_rel != t_rel else t_rel,
            "peak_contact_force": self.peak_contact_force,
            "peak_wrist_force": self.peak_wrist_force,
            "receiver_id": f"{rec.kind}:{rec.source_id}",
            "receiver_state": rec.state,
            "receiver_grasp_time": None if t_grasp != t_grasp else t_grasp,
            "transfer_time": None if t_grasp != t_grasp else t_grasp,
            "reach_onset_time": None if t_reach != t_reach else t_reach,
            "transfer_pelvis_xy": None
            if rec.grasp_pelvis_xy is None
            else tuple(rec.grasp_pelvis_xy.tolist()),
            "transfer_object_pos": (
                None
                if self.transfer_object_pos is None
                else tuple(self.transfer_object_pos.tolist())
            ),
            "transfer_object_body": rec.grasp_object_body,
            "transfer_object_speed": (None if rec.grasp_object_speed != rec.grasp_object_speed
                                      else rec.grasp_object_speed),
            "transfer_robot_jerk": (None if self.transfer_robot_jerk != self.transfer_robot_jerk
                                    else self.transfer_robot_jerk),
            "departure_time": t_depart,
            "within_calibration": rec.calibration.within,
            "reach_offset": rec.reach_offset.value,
            "pull_force": self.pull_force,
            "robot_jerk_rms": math.sqrt(self._jerk_sq / self._jerk_n) if self._jerk_n else 0.0,
            "robot_jerk_peak": math.sqrt(self._jerk_peak_sq),
            "time": self.data.time,
            "sensing": self.sensor_profile.name,
        }
        keys = _REWARD_KEYS
        for term, value in self.reward_terms.items():
            info[keys[term] if term in keys else f"reward_{term}"] = value
        info.update(rec.effort())
        info.update(self.contacts.entries)
        return info

    # ------------------------------------------------------------------ rendering
    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'"
            )
            return None
        if self.render_mode == "rgb_array":
            if self._renderer is None:
                self._renderer = mujoco.Renderer(self.model, self.height, self.width)
            self._renderer.update_scene(self.data, camera=self.camera)
            return self._renderer.render().copy()
        if self._viewer is None:
            from mujoco import viewer as mj_viewer

            self._viewer = mj_viewer.launch_passive(self.model, self.data)
        self._viewer.sync()
        return None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    def __getstate__(self):  # EzPickle rebuilds from the constructor kwargs
        return EzPickle.__getstate__(self)
