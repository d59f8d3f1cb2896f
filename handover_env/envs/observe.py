"""The observation vector, assembled in one compiled call (:func:`observe`; the layout is
:class:`handover_env.envs.observation.ObsLayout`'s, the env fills the integer table ``oi`` once and
the per-step values ``pv`` at every step).

The TCP orientation is MuJoCo's ``mju_mat2Quat`` of the site's rotation (normalised as
``mju_normalize4`` does), its twist MuJoCo's ``mj_objectVelocity`` of the site in the world frame
(``cvel`` of its body moved from the subtree's centre of mass to the site), the wrist torque
:func:`handover_env.envs.wrist_tick.wrist_torque`; then every part is clipped to the Box's bounds
(``min(x, high)``, then ``max(., low)``, as numpy's ``minimum``/``maximum``) and converted to
float32.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.compiled import kernel
from handover_env.envs import wrist_tick as wt

# oi (int64): starts in the vector of the layout's parts, the history W, offsets in MjData's array
O_HIST, O_SEEN, O_EEPOS, O_QUAT, O_LIN, O_ANG, O_OBJ, O_HELD = 0, 1, 2, 3, 4, 5, 6, 7
O_FORCE, O_TORQUE, O_OPEN, O_TIME, O_HAND, O_ENABLED, O_W = 8, 9, 10, 11, 12, 13, 14
M_TCP_POS, M_TCP_MAT, M_TCP_CVEL, M_TCP_COM, M_OBJ_POS = 15, 16, 17, 18, 19
OI_SIZE = 20
# pv (float64): per-step values
V_NHIST, V_SEEN, V_HELD, V_OPEN, V_TIME, V_ENABLED, V_HAND = 0, 1, 2, 3, 4, 5, 6
PV_SIZE = 9
MINVAL = 1e-15  # MuJoCo's mjMINVAL


@kernel
def observe(mem, obs, bounds, oi, pv, frames, ws):  # type: ignore[no-untyped-def]
    """Fill ``obs`` (float64) and return it clipped to ``bounds`` (rows low, high) as float32.

    ``frames`` holds the camera's delivered pelvis frames (rows [0, n), oldest first): the last
    W of them are the history, earlier rows repeat the first; ``ws`` is the wrist sensor's state.
    """
    w = oi[O_W]
    n = int(pv[V_NHIST])
    first = n - w if n > w else 0
    m = n - first
    h = oi[O_HIST]
    for r in range(w):
        src = first + (r - (w - m)) if r >= w - m else first
        obs[h + 2 * r] = frames[src, 0]
        obs[h + 2 * r + 1] = frames[src, 1]
    obs[oi[O_SEEN]] = pv[V_SEEN]
    p, o = oi[M_TCP_POS], oi[O_EEPOS]
    for k in range(3):
        obs[o + k] = mem[p + k]
    # mju_mat2Quat
    r = oi[M_TCP_MAT]
    m0, m1, m2 = mem[r], mem[r + 1], mem[r + 2]
    m3, m4, m5 = mem[r + 3], mem[r + 4], mem[r + 5]
    m6, m7, m8 = mem[r + 6], mem[r + 7], mem[r + 8]
    if m0 + m4 + m8 > 0:
        q0 = 0.5 * math.sqrt(1 + m0 + m4 + m8)
        q1 = 0.25 * (m7 - m5) / q0
        q2 = 0.25 * (m2 - m6) / q0
        q3 = 0.25 * (m3 - m1) / q0
    elif m0 > m4 and m0 > m8:
        q1 = 0.5 * math.sqrt(1 + m0 - m4 - m8)
        q0 = 0.25 * (m7 - m5) / q1
        q2 = 0.25 * (m1 + m3) / q1
        q3 = 0.25 * (m2 + m6) / q1
    elif m4 > m8:
        q2 = 0.5 * math.sqrt(1 - m0 + m4 - m8)
        q0 = 0.25 * (m2 - m6) / q2
        q1 = 0.25 * (m1 + m3) / q2
        q3 = 0.25 * (m5 + m7) / q2
    else:
        q3 = 0.5 * math.sqrt(1 - m0 - m4 + m8)
        q0 = 0.25 * (m3 - m1) / q3
        q1 = 0.25 * (m2 + m6) / q3
        q2 = 0.25 * (m5 + m7) / q3
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)  # mju_normalize4
    if norm < MINVAL:
        q0, q1, q2, q3 = 1.0, 0.0, 0.0, 0.0
    elif abs(norm - 1) > MINVAL:
        inv = 1 / norm
        q0, q1, q2, q3 = q0 * inv, q1 * inv, q2 * inv, q3 * inv
    o = oi[O_QUAT]
    obs[o], obs[o + 1], obs[o + 2], obs[o + 3] = q0, q1, q2, q3
    # mj_objectVelocity(site, world frame): [ω, v_com - (p - c) × ω]
    v, c = oi[M_TCP_CVEL], oi[M_TCP_COM]
    a0, a1, a2 = mem[v], mem[v + 1], mem[v + 2]
    d0, d1, d2 = mem[p] - mem[c], mem[p + 1] - mem[c + 1], mem[p + 2] - mem[c + 2]
    o = oi[O_LIN]
    obs[o] = mem[v + 3] - (d1 * a2 - d2 * a1)
    obs[o + 1] = mem[v + 4] - (d2 * a0 - d0 * a2)
    obs[o + 2] = mem[v + 5] - (d0 * a1 - d1 * a0)
    o = oi[O_ANG]
    obs[o], obs[o + 1], obs[o + 2] = a0, a1, a2
    p, o = oi[M_OBJ_POS], oi[O_OBJ]
    for k in range(3):
        obs[o + k] = mem[p + k]
    obs[oi[O_HELD]] = pv[V_HELD]
    wt.wrist_torque(mem, ws)
    o, t = oi[O_FORCE], oi[O_TORQUE]
    for k in range(3):
        obs[o + k] = ws[wt.F_EXT + k]
        obs[t + k] = ws[wt.TAU + k]
    obs[oi[O_OPEN]] = pv[V_OPEN]
    obs[oi[O_TIME]] = pv[V_TIME]
    o = oi[O_HAND]
    for k in range(3):
        obs[o + k] = pv[V_HAND + k]
    obs[oi[O_ENABLED]] = pv[V_ENABLED]
    size = obs.shape[0]
    out = np.empty(size, dtype=np.float32)
    for k in range(size):
        x = obs[k]
        hi, lo = bounds[1, k], bounds[0, k]
        x = hi if x > hi else x
        x = lo if x < lo else x
        out[k] = np.float32(x)
    return out
