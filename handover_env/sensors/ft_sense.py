"""The UR5e wrist sensor's 200 Hz step, compiled: :func:`ft_sense` on a
:class:`~handover_env.sensors.wrist_ft.WristFT`'s state array (steps 2-4 of that module's
docstring: offset, drift and white noise in the sensor frame, the tare, the filter).

The state array holds, at the slots below, the offset (``BIAS``), the tare (``OFFSET``), the
filtered reading (``FILT``), the last noise-free reading (``CLEAN``), whether a reading was made
(``STARTED``), whether the sensor draws random numbers (``DRAWS``), the drift and noise scales,
the filter gain, and a block of standard normals (``NORMALS``, six per tick: noise x, y, z,
drift x, y, z) with the index of the next one (``ZI``). The block is drawn by the caller
(:meth:`~handover_env.sensors.wrist_ft.WristFT.refill`) before a tick that finds it used up, so
the Generator's stream is the same as drawing six normals per tick from blocks of 256 ticks.
"""

from __future__ import annotations

from handover_env.compiled import kernel

BIAS, OFFSET, FILT, CLEAN = 0, 3, 6, 9
STARTED, DRAWS, DRIFT_STEP, NOISE_SCALE, GAIN, ZI = 12, 13, 14, 15, 16, 17
NORMALS = 18
BLOCK = 256  # ticks of random numbers drawn from the Generator at a time
SIZE = NORMALS + 6 * BLOCK


@kernel
def ft_sense(st, gx, gy, gz, r, ir):  # type: ignore[no-untyped-def]
    """One tick: the filtered reading (world frame, N) from the force the robot computes with its
    configured payload (``gx, gy, gz``, world frame) and the sensor-to-world rotation (9 numbers,
    row-major, at ``r[ir:]``); updates ``st``. The normals must not be used up (``st[ZI]`` <
    ``6 * BLOCK``) when the sensor draws."""
    r00, r01, r02 = r[ir], r[ir + 1], r[ir + 2]
    r10, r11, r12 = r[ir + 3], r[ir + 4], r[ir + 5]
    r20, r21, r22 = r[ir + 6], r[ir + 7], r[ir + 8]
    b0, b1, b2 = st[BIAS], st[BIAS + 1], st[BIAS + 2]
    # sensor frame: Rᵀ g + bias (the noise-free reading a tare would see)
    c0 = r00 * gx + r10 * gy + r20 * gz + b0
    c1 = r01 * gx + r11 * gy + r21 * gz + b1
    c2 = r02 * gx + r12 * gy + r22 * gz + b2
    st[CLEAN], st[CLEAN + 1], st[CLEAN + 2] = c0, c1, c2
    if st[DRAWS] != 0.0:
        i = NORMALS + int(st[ZI])
        st[ZI] += 6.0
        k = st[DRIFT_STEP]
        st[BIAS] = b0 + k * st[i + 3]
        st[BIAS + 1] = b1 + k * st[i + 4]
        st[BIAS + 2] = b2 + k * st[i + 5]
        k = st[NOISE_SCALE]
        c0, c1, c2 = c0 + k * st[i], c1 + k * st[i + 1], c2 + k * st[i + 2]
    c0, c1, c2 = c0 - st[OFFSET], c1 - st[OFFSET + 1], c2 - st[OFFSET + 2]
    mx = r00 * c0 + r01 * c1 + r02 * c2
    my = r10 * c0 + r11 * c1 + r12 * c2
    mz = r20 * c0 + r21 * c1 + r22 * c2
    if st[STARTED] == 0.0:
        st[STARTED] = 1.0
        st[FILT], st[FILT + 1], st[FILT + 2] = mx, my, mz
        return mx, my, mz
    a = st[GAIN]
    fx, fy, fz = st[FILT], st[FILT + 1], st[FILT + 2]
    fx, fy, fz = fx + a * (mx - fx), fy + a * (my - fy), fz + a * (mz - fz)
    st[FILT], st[FILT + 1], st[FILT + 2] = fx, fy, fz
    return fx, fy, fz
