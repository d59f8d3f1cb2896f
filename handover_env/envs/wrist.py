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
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from handover_env.robot.scene import SceneIds


class WristSensor:
    """The external wrist wrench of a compiled handover scene, from its F/T and IMU readings.

    Args:
        model, data: the compiled scene and its state (views of ``data`` are kept: it must live
            as long as the sensor).
        ids: scene indices.
        ticks: physics steps per controller tick (the filter's update interval).
        filter_tau: s, time constant of the force's first-order low-pass filter.

    Attributes:
        f_ext: (3,) the filtered external force, N (world frame), updated at every tick.
        tau_ext: (3,) the external torque, N m (world frame), as of the last :meth:`torque`.
    """

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData, ids: SceneIds, ticks: int,
        filter_tau: float,
    ) -> None:
        self.model, self.data, self.ids = model, data, ids
        self._filter_alpha = (ticks * model.opt.timestep) / (
            filter_tau + ticks * model.opt.timestep
        )
        d = data
        adrs = (ids.ft_force_adr, ids.ft_torque_adr, ids.ft_acc_adr)
        lo = min(adrs)
        self._ft_v = d.sensordata[lo:max(adrs) + 3]  # force, torque and accelerometer readings
        self._ft_force_i, self._ft_torque_i, self._ft_acc_i = (a - lo for a in adrs)
        self._ft_xmat_v = d.site_xmat[ids.ft_site]
        self._grip_w_v = d.cvel[ids.gripper_root_body, 0:3]
        self._grip_alpha_v = d.cacc[ids.gripper_root_body, 0:3]
        self.reset()

    def reset(self) -> None:
        """No force measured yet (a new episode); the filter starts from zero."""
        self.f_ext = np.zeros(3)
        self._f_ext_f = (0.0, 0.0, 0.0)
        self.tau_ext = np.zeros(3)

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

    def tick(self) -> float:
        """Estimate and filter the external force at this tick; returns its magnitude, N.

        Done in plain floats (3-vectors are cheaper that way than as numpy arrays); see the
        module docstring for the formula.
        """
        ft = self._ft_v.tolist()
        m_p = self._payload_mass
        i = self._ft_acc_i
        a0, a1, a2 = ft[i], ft[i + 1], ft[i + 2]
        i = self._ft_force_i
        s0, s1, s2 = ft[i], ft[i + 1], ft[i + 2]
        l0, l1, l2 = m_p * a0 - s0, m_p * a1 - s1, m_p * a2 - s2  # site frame
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = self._ft_xmat_v.tolist()
        c0, c1, c2 = self._payload_com_f
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
        k = self._filter_alpha
        fx, fy, fz = self._f_ext_f
        fx += k * (gx - fx)
        fy += k * (gy - fy)
        fz += k * (gz - fz)
        self._f_ext_f = (fx, fy, fz)
        self.f_ext[0], self.f_ext[1], self.f_ext[2] = fx, fy, fz
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
