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

    Attributes:
        f_ext: (3,) the measured (filtered) external force, N (world frame), updated at every
            tick: what the release compares with f_r and the agent observes.
        f_true: (3,) the exact filtered estimate (the same array as ``f_ext`` without a sensor
            model).
        ft: the episode's UR5e sensor model, or None (exact).
        tau_ext: (3,) the external torque, N m (world frame), as of the last :meth:`torque`.
    """

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData, ids: SceneIds, ticks: int,
        filter_tau: float,
    ) -> None:
        self.model, self.data, self.ids = model, data, ids
        self._tick_dt = ticks * model.opt.timestep
        self.set_filter_tau(filter_tau)
        self.ft: WristFT | None = None
        d = data
        adrs = (ids.ft_force_adr, ids.ft_torque_adr, ids.ft_acc_adr)
        lo = min(adrs)
        self._ft_v = d.sensordata[lo:max(adrs) + 3]  # force, torque and accelerometer readings
        self._ft_force_i, self._ft_torque_i, self._ft_acc_i = (a - lo for a in adrs)
        self._ft_xmat_v = d.site_xmat[ids.ft_site]
        self._grip_w_v = d.cvel[ids.gripper_root_body, 0:3]
        self._grip_alpha_v = d.cacc[ids.gripper_root_body, 0:3]
        self.reset()

    def set_filter_tau(self, filter_tau: float) -> None:
        """The force filter's time constant, s (first order, updated at every tick)."""
        if not math.isfinite(filter_tau) or filter_tau < 0:
            raise ValueError(f"filter_tau must be a finite number >= 0 s, got {filter_tau!r}")
        self._filter_alpha = self._tick_dt / (filter_tau + self._tick_dt)

    def reset(self) -> None:
        """No force measured yet (a new episode); the filter starts from zero."""
        self.f_ext = np.zeros(3)
        self._f_ext_f = (0.0, 0.0, 0.0)
        self.f_true = self.f_ext
        self._f_true_f = (0.0, 0.0, 0.0)
        self.tau_ext = np.zeros(3)

    def start(self, params: WristFTParams, rng: np.random.Generator) -> None:
        """An episode's sensor (call after :meth:`update_payload`, the arm settled at the ready
        pose): the filter of ``params``; with any sensor error or zeroing, the UR5e model
        (:class:`handover_env.sensors.WristFT`, its errors drawn from ``rng``), measured once here
        and zeroed (URScript ``zero_ftsensor()``, docs/sensing.md). Without them (the "ideal"
        profile) the exact estimate is the reading and nothing is drawn."""
        self.set_filter_tau(params.filter_tau)
        exact = (params.precision == 0.0 and params.accuracy == 0.0 and params.drift == 0.0
                 and params.mass_error == 0.0 and params.com_error == 0.0 and not params.zeroing)
        if exact:
            self.ft = None
            self.f_true = self.f_ext
            return
        self.f_true = np.zeros(3)
        self._f_true_f = (0.0, 0.0, 0.0)
        self.ft = WristFT(params).reset(rng, self._payload_mass, self._payload_com, self._tick_dt)
        self._configure()
        g = self._estimate(self._conf_mass, self._conf_com_f)
        self.ft.sense(g[0], g[1], g[2], self._ft_xmat_v.tolist())
        self.ft.zero()
        self._f_ext_f = (0.0, 0.0, 0.0)
        self.f_ext[:] = 0.0

    def _configure(self) -> None:
        """The configured payload (mass, centre of mass in the site frame) from the model."""
        ft = self.ft
        assert ft is not None
        self._conf_mass = ft.configured_mass
        self._conf_com_f = tuple(ft.configured_com.tolist())

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
        self._payload_com_f = tuple(self._payload_com.tolist())
        if self.ft is not None:  # the configured payload keeps the episode's errors
            self.ft.set_payload(mass, self._payload_com)
            self._configure()

    def _estimate(self, m_p: float, c: tuple[float, float, float]) -> tuple[float, float, float]:
        """The external force (world frame, unfiltered) with payload mass ``m_p`` and centre of
        mass ``c`` (site frame), in plain floats (3-vectors are cheaper that way than as numpy
        arrays); see the module docstring for the formula."""
        ft = self._ft_v.tolist()
        i = self._ft_acc_i
        a0, a1, a2 = ft[i], ft[i + 1], ft[i + 2]
        i = self._ft_force_i
        s0, s1, s2 = ft[i], ft[i + 1], ft[i + 2]
        l0, l1, l2 = m_p * a0 - s0, m_p * a1 - s1, m_p * a2 - s2  # site frame
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = self._ft_xmat_v.tolist()
        c0, c1, c2 = c
        cx = r00 * c0 + r01 * c1 + r02 * c2
        cy = r10 * c0 + r11 * c1 + r12 * c2
        cz = r20 * c0 + r21 * c1 + r22 * c2
        # Rigid-payload inertia beyond the site's linear acceleration: m (α × c + ω × (ω × c)),
        # with ω, α of the gripper (world frame, from cvel/cacc) and c its centre of mass.
        wx, wy, wz = self._grip_w_v.tolist()
        ax, ay, az = self._grip_alpha_v.tolist()
        vx, vy, vz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx  # ω × c
        gx = r00 * l0 + r01 * l1 + r02 * l2 + m_p * (ay * cz - az * cy + wy * vz - wz * vy)
        gy = r10 * l0 + r11 * l1 + r12 * l2 + m_p * (az * cx - ax * cz + wz * vx - wx * vz)
        gz = r20 * l0 + r21 * l1 + r22 * l2 + m_p * (ax * cy - ay * cx + wx * vy - wy * vx)
        return gx, gy, gz

    def _both(self) -> tuple[float, ...]:
        """The exact estimate (true payload) and the configured-payload one, (gx, gy, gz, hx, hy,
        hz), from one read of the sensors: :meth:`_estimate` twice, sharing the reads."""
        ft = self._ft_v.tolist()
        i = self._ft_acc_i
        a0, a1, a2 = ft[i], ft[i + 1], ft[i + 2]
        i = self._ft_force_i
        s0, s1, s2 = ft[i], ft[i + 1], ft[i + 2]
        r = self._ft_xmat_v.tolist()
        self._r = r
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
        wx, wy, wz = self._grip_w_v.tolist()
        ax, ay, az = self._grip_alpha_v.tolist()
        out = []
        for m_p, (c0, c1, c2) in ((self._payload_mass, self._payload_com_f),
                                  (self._conf_mass, self._conf_com_f)):
            l0, l1, l2 = m_p * a0 - s0, m_p * a1 - s1, m_p * a2 - s2
            cx = r00 * c0 + r01 * c1 + r02 * c2
            cy = r10 * c0 + r11 * c1 + r12 * c2
            cz = r20 * c0 + r21 * c1 + r22 * c2
            vx, vy, vz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
            ex = m_p * (ay * cz - az * cy + wy * vz - wz * vy)
            ey = m_p * (az * cx - ax * cz + wz * vx - wx * vz)
            ez = m_p * (ax * cy - ay * cx + wx * vy - wy * vx)
            out.append(r00 * l0 + r01 * l1 + r02 * l2 + ex)
            out.append(r10 * l0 + r11 * l1 + r12 * l2 + ey)
            out.append(r20 * l0 + r21 * l1 + r22 * l2 + ez)
        return tuple(out)

    def tick(self) -> float:
        """Estimate and filter the external force at this tick; returns the measured magnitude, N.

        The exact estimate (true payload) is filtered into :attr:`f_true`. With the UR5e model
        (:meth:`start`) the reading is the estimate with the *configured* payload through the
        sensor's errors, tare and filter (:meth:`handover_env.sensors.WristFT.sense`); without it
        the reading is the exact estimate.
        """
        ft = self.ft
        if ft is None:
            gx, gy, gz = self._estimate(self._payload_mass, self._payload_com_f)
        else:
            gx, gy, gz, hx, hy, hz = self._both()
        k = self._filter_alpha
        fx, fy, fz = self._f_true_f
        fx += k * (gx - fx)
        fy += k * (gy - fy)
        fz += k * (gz - fz)
        self._f_true_f = (fx, fy, fz)
        if ft is not None:
            f_true = self.f_true
            f_true[0], f_true[1], f_true[2] = fx, fy, fz
            fx, fy, fz = ft.sense(hx, hy, hz, self._r)
        self._f_ext_f = (fx, fy, fz)
        self.f_ext[0], self.f_ext[1], self.f_ext[2] = fx, fy, fz
        return math.sqrt(fx * fx + fy * fy + fz * fz)

    def true_magnitude(self) -> float:
        """N, the exact (filtered) external force's magnitude."""
        fx, fy, fz = self._f_true_f
        return math.sqrt(fx * fx + fy * fy + fz * fz)

    def magnitude(self) -> float:
        """N, the filtered external force's magnitude (what the release compares with f_r)."""
        fx, fy, fz = self._f_ext_f
        return math.sqrt(fx * fx + fy * fy + fz * fz)

    def torque(self) -> np.ndarray:
        """External torque at the sensor (world frame), static load removed (per env step)."""
        ft = self._ft_v.tolist()
        m_p = self._payload_mass
        i = self._ft_acc_i
        l0, l1, l2 = m_p * ft[i], m_p * ft[i + 1], m_p * ft[i + 2]
        i = self._ft_torque_i
        c0, c1, c2 = self._payload_com_f
        t0 = (c1 * l2 - c2 * l1) - ft[i]
        t1 = (c2 * l0 - c0 * l2) - ft[i + 1]
        t2 = (c0 * l1 - c1 * l0) - ft[i + 2]
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = self._ft_xmat_v.tolist()
        self.tau_ext = np.array([r00 * t0 + r01 * t1 + r02 * t2, r10 * t0 + r11 * t1 + r12 * t2,
                                 r20 * t0 + r21 * t1 + r22 * t2])
        return self.tau_ext
