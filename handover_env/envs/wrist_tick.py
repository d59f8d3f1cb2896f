"""The wrist sensor's 200 Hz tick, compiled (:class:`handover_env.envs.wrist.WristSensor` keeps the
state array ``ws`` and calls :func:`wrist_tick`).

``ws`` holds the payload (true mass and centre of mass in the sensor frame; the configured ones
of the UR5e model), the filter gain, the filtered exact force (``F_TRUE``), the reading
(``F_EXT``), whether the UR5e model is on (``MODEL``), and the offsets in MjData's array
(:class:`handover_env.mjdata_view.MjDataView`) of the force and accelerometer readings, the F/T
site's rotation and the gripper's angular velocity and acceleration (``cvel``/``cacc``).
The formula is the module docstring's of :mod:`handover_env.envs.wrist`, in its order of
operations.
"""

from __future__ import annotations

import math

from handover_env.compiled import kernel
from handover_env.sensors.ft_sense import BLOCK, DRAWS, ZI, ft_sense

MASS, COM, CONF_MASS, CONF_COM, GAIN, F_TRUE, F_EXT, MODEL = 0, 1, 4, 5, 8, 9, 12, 15
O_FORCE, O_ACC, O_TORQUE, O_XMAT, O_OMEGA, O_ALPHA = 16, 17, 18, 19, 20, 21
TAU = 22  # the external torque (world frame) as of the last wrist_torque
SIZE = 25


@kernel
def wrist_estimate(mem, ws, m_p, c0, c1, c2):  # type: ignore[no-untyped-def]
    """The external force (world frame, unfiltered) with payload mass ``m_p`` and centre of mass
    ``c`` (sensor frame): ``R (m a - F) + m (α × c + ω × (ω × c))``."""
    i = int(ws[O_ACC])
    a0, a1, a2 = mem[i], mem[i + 1], mem[i + 2]
    i = int(ws[O_FORCE])
    s0, s1, s2 = mem[i], mem[i + 1], mem[i + 2]
    i = int(ws[O_XMAT])
    r00, r01, r02 = mem[i], mem[i + 1], mem[i + 2]
    r10, r11, r12 = mem[i + 3], mem[i + 4], mem[i + 5]
    r20, r21, r22 = mem[i + 6], mem[i + 7], mem[i + 8]
    i = int(ws[O_OMEGA])
    wx, wy, wz = mem[i], mem[i + 1], mem[i + 2]
    i = int(ws[O_ALPHA])
    ax, ay, az = mem[i], mem[i + 1], mem[i + 2]
    l0, l1, l2 = m_p * a0 - s0, m_p * a1 - s1, m_p * a2 - s2  # site frame
    cx = r00 * c0 + r01 * c1 + r02 * c2
    cy = r10 * c0 + r11 * c1 + r12 * c2
    cz = r20 * c0 + r21 * c1 + r22 * c2
    vx, vy, vz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx  # ω × c
    ex = m_p * (ay * cz - az * cy + wy * vz - wz * vy)
    ey = m_p * (az * cx - ax * cz + wz * vx - wx * vz)
    ez = m_p * (ax * cy - ay * cx + wx * vy - wy * vx)
    return (r00 * l0 + r01 * l1 + r02 * l2 + ex,
            r10 * l0 + r11 * l1 + r12 * l2 + ey,
            r20 * l0 + r21 * l1 + r22 * l2 + ez)


@kernel
def wrist_tick(mem, ws, ft):  # type: ignore[no-untyped-def]
    """Estimate and filter the external force at this tick; returns the reading's magnitude, N.

    The exact estimate (true payload) is filtered into ``F_TRUE``; with the UR5e model on, the
    reading is the configured-payload estimate through the sensor model (``ft``, the state of
    :class:`~handover_env.sensors.wrist_ft.WristFT`), else the exact one. Returns -1 and changes
    nothing when the sensor model has used up its normals (the caller draws the next block and
    calls again)."""
    if ws[MODEL] != 0.0 and ft[DRAWS] != 0.0 and ft[ZI] >= 6 * BLOCK:
        return -1.0
    gx, gy, gz = wrist_estimate(mem, ws, ws[MASS], ws[COM], ws[COM + 1], ws[COM + 2])
    k = ws[GAIN]
    fx, fy, fz = ws[F_TRUE], ws[F_TRUE + 1], ws[F_TRUE + 2]
    fx += k * (gx - fx)
    fy += k * (gy - fy)
    fz += k * (gz - fz)
    ws[F_TRUE], ws[F_TRUE + 1], ws[F_TRUE + 2] = fx, fy, fz
    if ws[MODEL] != 0.0:
        hx, hy, hz = wrist_estimate(mem, ws, ws[CONF_MASS], ws[CONF_COM], ws[CONF_COM + 1],
                                    ws[CONF_COM + 2])
        fx, fy, fz = ft_sense(ft, hx, hy, hz, mem, int(ws[O_XMAT]))
    ws[F_EXT], ws[F_EXT + 1], ws[F_EXT + 2] = fx, fy, fz
    return math.sqrt(fx * fx + fy * fy + fz * fz)


@kernel
def wrist_torque(mem, ws):  # type: ignore[no-untyped-def]
    """External torque at the sensor (world frame), static load removed, into ``ws[TAU:]``:
    ``R ((c × m a) - T)`` with the true payload (mass m, centre of mass c in the sensor frame)."""
    m_p = ws[MASS]
    i = int(ws[O_ACC])
    l0, l1, l2 = m_p * mem[i], m_p * mem[i + 1], m_p * mem[i + 2]
    i = int(ws[O_TORQUE])
    c0, c1, c2 = ws[COM], ws[COM + 1], ws[COM + 2]
    t0 = (c1 * l2 - c2 * l1) - mem[i]
    t1 = (c2 * l0 - c0 * l2) - mem[i + 1]
    t2 = (c0 * l1 - c1 * l0) - mem[i + 2]
    i = int(ws[O_XMAT])
    ws[TAU] = mem[i] * t0 + mem[i + 1] * t1 + mem[i + 2] * t2
    ws[TAU + 1] = mem[i + 3] * t0 + mem[i + 4] * t1 + mem[i + 5] * t2
    ws[TAU + 2] = mem[i + 6] * t0 + mem[i + 7] * t1 + mem[i + 8] * t2
