"""The wrist force/torque sensor: the external wrench at the UR5e flange, static load removed.

The ``force``/``torque`` sensors on the gripper mounting plate measure what the gripper, plus
anything it holds, exerts on the flange. The static load is subtracted with the payload's known
mass and the ``accelerometer`` at the same site (which reads a - g), plus the rigid payload's
rotational inertia terms: ``F_ext = R (m acc - F_sensor) + m (α × c + ω × (ω × c))`` with ω, α
the gripper's angular velocity and acceleration and c the payload's centre of mass relative to
the site (world frame): the force the world applies to gripper and object. The rotational terms
matter while the arm swings the object toward the receiver: without them the estimate is off by
up to about 5 N, close to f_r; with them, by about 0.2 N. The torque (observation only) is the
quasi-static estimate with the payload's centre of mass.

The force estimate is low-pass filtered (first order, time constant ``filter_tau``) at every
200 Hz controller tick, like a real F/T signal; the torque is estimated at the env rate for the
observation. When the force's magnitude exceeds f_r the gripper opens (paper Sec. IV-C; the env
compares).

What the robot measures (issue 24, docs/sensing.md): with a sensor profile that has errors,
:meth:`WristSensor.start` attaches the UR5e wrist model (:class:`handover_env.sensors.WristFT`):
the same estimate computed with the *configured* payload (mass and centre of mass off by the
episode's errors), plus the sensor's offset, drift and white noise, tared once at the episode
start; the release and the observation use that reading (:attr:`WristSensor.f_ext`), the exact
one is kept as :attr:`WristSensor.f_true`. The torque (observation only) stays the exact
estimate: the model covers the force the release uses.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from handover_env.envs import wrist_tick as wt
from handover_env.mjdata_view import MjDataView
from handover_env.robot.scene import SceneIds
from handover_env.sensors import WristFT, WristFTParams


class WristSensor:
    """The external wrist wrench of a compiled handover scene, from its F/T and IMU readings.

    Args:
        model, data: the compiled scene and its state (views of ``data`` are kept: it must live
            as long as the sensor).
        ids: scene indices.
        ticks: physics steps per controller tick (the filter's update interval).
        filter_tau: s, time constant of the force's first-order low-pass filter.
        view: ``data`` as one array for the compiled tick (made here if not given).

    Attributes:
        f_ext: (3,) the measured (filtered) external force, N (world frame), updated at every
            tick: what the release compares with f_r and the agent observes.
        f_true: (3,) the exact filtered estimate.
        ft: the episode's UR5e sensor model, or None (exact).
        tau_ext: (3,) the external torque, N m (world frame), as of the last :meth:`torque`.
        state: the compiled tick's state (:mod:`handover_env.envs.wrist_tick`); ``f_ext``,
            ``f_true`` and ``tau_ext`` are views of it.
    """

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData, ids: SceneIds, ticks: int,
        filter_tau: float, view: MjDataView | None = None,
    ) -> None:
        self.model, self.data, self.ids = model, data, ids
        self.view = view if view is not None else MjDataView(data)
        self.state = st = np.zeros(wt.SIZE)
        self.f_ext = st[wt.F_EXT:wt.F_EXT + 3]
        self.f_true = st[wt.F_TRUE:wt.F_TRUE + 3]
        self.tau_ext = st[wt.TAU:wt.TAU + 3]
        self._no_model = np.zeros(1)  # the sensor-model argument when there is no model
        self._ft_state = self._no_model
        self._tick_dt = ticks * model.opt.timestep
        self.set_filter_tau(filter_tau)
        self.ft: WristFT | None = None
        v = self.view
        st[wt.O_FORCE] = v.offset("sensordata") + ids.ft_force_adr
        st[wt.O_ACC] = v.offset("sensordata") + ids.ft_acc_adr
        st[wt.O_TORQUE] = v.offset("sensordata") + ids.ft_torque_adr
        st[wt.O_XMAT] = v.offset("site_xmat", ids.ft_site)
        st[wt.O_OMEGA] = v.offset("cvel", ids.gripper_root_body)
        st[wt.O_ALPHA] = v.offset("cacc", ids.gripper_root_body)
        self._ft_xmat_v = data.site_xmat[ids.ft_site]
        self.reset()

    def set_filter_tau(self, filter_tau: float) -> None:
        """The force filter's time constant, s (first order, updated at every tick)."""
        if not math.isfinite(filter_tau) or filter_tau < 0:
            raise ValueError(f"filter_tau must be a finite number >= 0 s, got {filter_tau!r}")
        self.state[wt.GAIN] = self._tick_dt / (filter_tau + self._tick_dt)

    def reset(self) -> None:
        """No force measured yet (a new episode); the filter starts from zero."""
        self.f_ext[:] = 0.0
        self.f_true[:] = 0.0
        self.tau_ext[:] = 0.0

    def start(self, params: WristFTParams, rng: np.random.Generator) -> None:
        """An episode's sensor (call after :meth:`update_payload`, the arm settled at the ready
        pose): the filter of ``params``; with any sensor error or zeroing, the UR5e model
        (:class:`handover_env.sensors.WristFT`, its errors drawn from ``rng``), measured once here
        and zeroed (URScript ``zero_ftsensor()``, docs/sensing.md). Without them (the "ideal"
        profile) the exact estimate is the reading and nothing is drawn."""
        self.set_filter_tau(params.filter_tau)
        exact = (params.precision == 0.0 and params.accuracy == 0.0 and params.drift == 0.0
                 and params.mass_error == 0.0 and params.com_error == 0.0 and not params.zeroing)
        st = self.state
        if exact:
            self.ft = None
            self._ft_state = self._no_model
            st[wt.MODEL] = 0.0
            return
        st[wt.MODEL] = 1.0
        self.ft = WristFT(params).reset(rng, self._payload_mass, self._payload_com, self._tick_dt)
        self._ft_state = self.ft.state
        self._configure()
        g = wt.wrist_estimate(self.view.mem, st, st[wt.CONF_MASS], st[wt.CONF_COM],
                              st[wt.CONF_COM + 1], st[wt.CONF_COM + 2])
        self.ft.sense(g[0], g[1], g[2], self._ft_xmat_v)
        self.ft.zero()
        self.f_ext[:] = 0.0

    def _configure(self) -> None:
        """The configured payload (mass, centre of mass in the site frame) from the model."""
        ft = self.ft
        assert ft is not None
        st = self.state
        st[wt.CONF_MASS] = ft.configured_mass
        st[wt.CONF_COM:wt.CONF_COM + 3] = ft.configured_com

    def update_payload(self, holds_object: bool) -> None:
        """Mass and centre of mass (in the F/T site frame) of what hangs below the sensor: the
        gripper, and the object while ``holds_object``."""
        m, d, ids = self.model, self.data, self.ids
        mass = float(m.body_subtreemass[ids.gripper_root_body])
        com = d.subtree_com[ids.gripper_root_body] * mass
        if holds_object:
            mo = float(m.body_mass[ids.object_body])
            com = com + d.xipos[ids.object_body] * mo
            mass += mo
        com = com / mass
        rot = d.site_xmat[ids.ft_site].reshape(3, 3)
        self._payload_mass = mass
        self._payload_com = rot.T @ (com - d.site_xpos[ids.ft_site])
        st = self.state
        st[wt.MASS] = mass
        st[wt.COM:wt.COM + 3] = self._payload_com
        if self.ft is not None:  # the configured payload keeps the episode's errors
            self.ft.set_payload(mass, self._payload_com)
            self._configure()

    def tick(self) -> float:
        """Estimate and filter the external force at this tick; returns the measured magnitude, N
        (:func:`handover_env.envs.wrist_tick.wrist_tick`).

        The exact estimate (true payload) is filtered into :attr:`f_true`. With the UR5e model
        (:meth:`start`) the reading is the estimate with the *configured* payload through the
        sensor's errors, tare and filter (:meth:`handover_env.sensors.WristFT.sense`); without it
        the reading is the exact estimate.
        """
        f = wt.wrist_tick(self.view.mem, self.state, self._ft_state)
        if f < 0.0:  # the sensor model's normals are used up: the next block, then the tick
            self.ft.refill()  # type: ignore[union-attr]
            f = wt.wrist_tick(self.view.mem, self.state, self._ft_state)
        return f

    def true_magnitude(self) -> float:
        """N, the exact (filtered) external force's magnitude."""
        fx, fy, fz = self.f_true.tolist()
        return math.sqrt(fx * fx + fy * fy + fz * fz)

    def magnitude(self) -> float:
        """N, the filtered external force's magnitude (what the release compares with f_r)."""
        fx, fy, fz = self.f_ext.tolist()
        return math.sqrt(fx * fx + fy * fy + fz * fz)

    def torque(self) -> np.ndarray:
        """External torque at the sensor (world frame), static load removed (per env step; a
        copy of :attr:`tau_ext`, :func:`handover_env.envs.wrist_tick.wrist_torque`)."""
        wt.wrist_torque(self.view.mem, self.state)
        return self.tau_ext.copy()
