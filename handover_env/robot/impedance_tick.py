"""The impedance controller's 200 Hz tick, compiled (:class:`handover_env.robot.controller.
ImpedanceController` builds its buffers and calls :func:`impedance_tick`).

One call does, by the bits of ``phase``:

- :data:`JAC`: the TCP's Jacobian from ``cdof`` and ``subtree_com``, as MuJoCo's ``mj_jac``
  computes it (rotation rows ``cdof[:3]``, translation rows ``cdof[3:] + cdof[:3] × (p - c)``,
  over the dofs of the TCP body's chain), after keeping the previous tick's;
- :data:`WRENCH`: ``z`` (TCP position, the twists ``J q̇`` and ``J_prev q̇`` over all dofs, the
  orientation) and ``[wrench, trace(R_d Rᵀ)] = W_i z``;
- :data:`TORQUE`: ``τ = Jᵀ F + qfrc_bias + τ_posture``, and with a joint speed or acceleration
  limit the joint accelerations ``q̈ = M_arm^-1 (τ - c)`` checked against their bounds;
- :data:`CLIP`: τ clipped to the torque limits, kept and written to the arm's ``ctrl``.

The products are MuJoCo's (``mju_mulMatVec``, ``mju_mulMatTVec``) in MuJoCo's order
(:func:`handover_env.kernel_math.mj_dot`), so the tick gives the same bits as those calls.
It returns :data:`DONE`, or stops early with :data:`FAR_ROTATION` (orientation error beyond
~120 deg: the caller rescales the rotational wrench, then asks for ``TORQUE | CLIP``) or
:data:`LIMITED` (a joint acceleration out of its bounds: the correction is in the ``corr`` buffer,
the caller applies it, then asks for ``CLIP``). Both are rare; the caller's code for them is
numpy's (a matrix inverse).
"""

from __future__ import annotations

from handover_env.compiled import kernel
from handover_env.kernel_math import mj_dot

JAC, WRENCH, TORQUE, CLIP = 1, 2, 4, 8
ALL = JAC | WRENCH | TORQUE | CLIP
DONE, FAR_ROTATION, LIMITED = 0, 1, 2

# Integer workspace (int64): sizes, offsets in MjData's array and the float workspace, state.
I_NV, I_NCHAIN, I_HAVE_PREV, I_LIMIT = 0, 1, 2, 3
I_XPOS, I_XMAT, I_QVEL, I_CDOF, I_COM, I_BIAS, I_CTRL = 4, 5, 6, 7, 8, 9, 10
I_JAC, I_W, I_Z, I_OUT, I_TAUF, I_TAU, I_POST, I_LIMITS, I_LAST = 11, 12, 13, 14, 15, 16, 17, 18, 19
I_MINV, I_ACC, I_CORR, I_SCAL, I_LIST = 20, 21, 22, 23, 24
I_SIZE = 32  # the fixed slots; then the chain dofs, the 6 arm dofs and the 6 arm actuators
# Scalars (float workspace at iw[I_SCAL]): payload weight factor 9.81 m, joint speed limit,
# joint acceleration limit, 1 / tick.
S_GM, S_VLIM, S_ALIM, S_INV_DT = 0, 1, 2, 3
Z_SIZE = 26
N_ARM = 6


@kernel
def impedance_tick(mem, fw, iw, i, phase):  # type: ignore[no-untyped-def]
    """One controller tick on MjData's array ``mem`` and the controller's workspaces ``fw``
    (float64) and ``iw`` (int64), planned tick ``i``; see the module docstring."""
    nv = iw[I_NV]
    nchain = iw[I_NCHAIN]
    chain = I_SIZE
    arm = chain + nchain
    act = arm + N_ARM
    jac = iw[I_JAC]  # (12, nv): rows 0:3 J_p, 3:6 J_r, 6:12 the previous tick's
    if phase & JAC:
        if iw[I_HAVE_PREV]:
            for k in range(6 * nv):
                fw[jac + 6 * nv + k] = fw[jac + k]
        xp, com, cdof = iw[I_XPOS], iw[I_COM], iw[I_CDOF]
        o0 = mem[xp] - mem[com]
        o1 = mem[xp + 1] - mem[com + 1]
        o2 = mem[xp + 2] - mem[com + 2]
        for c in range(nchain):
            da = iw[chain + c]
            d = cdof + 6 * da
            a0, a1, a2 = mem[d], mem[d + 1], mem[d + 2]
            fw[jac + 3 * nv + da] = a0
            fw[jac + 4 * nv + da] = a1
            fw[jac + 5 * nv + da] = a2
            fw[jac + da] = mem[d + 3] + (a1 * o2 - a2 * o1)
            fw[jac + nv + da] = mem[d + 4] + (a2 * o0 - a0 * o2)
            fw[jac + 2 * nv + da] = mem[d + 5] + (a0 * o1 - a1 * o0)
        if not iw[I_HAVE_PREV]:
            for k in range(6 * nv):
                fw[jac + 6 * nv + k] = fw[jac + k]
            iw[I_HAVE_PREV] = 1
    out = iw[I_OUT]
    if phase & WRENCH:
        z = iw[I_Z]
        xp, xm, qv = iw[I_XPOS], iw[I_XMAT], iw[I_QVEL]
        for k in range(3):
            fw[z + k] = mem[xp + k]
        for k in range(9):
            fw[z + 17 + k] = mem[xm + k]
        for r in range(12):
            fw[z + 3 + r] = mj_dot(fw, jac + r * nv, mem, qv, nv)
        w = iw[I_W] + i * 7 * Z_SIZE
        for r in range(7):
            fw[out + r] = mj_dot(fw, w + r * Z_SIZE, fw, z, Z_SIZE)
        if fw[out + 6] < -0.5:  # trace(R_d Rᵀ): beyond ~120 deg
            return FAR_ROTATION
    tau = iw[I_TAU]
    if phase & TORQUE:
        tf = iw[I_TAUF]
        for k in range(nv):
            fw[tf + k] = 0.0
        for r in range(6):  # mju_mulMatTVec: rows with a zero coefficient are skipped
            f = fw[out + r]
            if f != 0.0:
                row = jac + r * nv
                for k in range(nv):
                    fw[tf + k] += fw[row + k] * f
        bias, post = iw[I_BIAS], iw[I_POST]
        for k in range(N_ARM):
            dof = iw[arm + k]
            fw[tau + k] = fw[tf + dof] + mem[bias + dof]
            fw[tau + k] += fw[post + k]
        if iw[I_LIMIT]:
            s = iw[I_SCAL]
            gm, vlim, alim, inv_h = fw[s + S_GM], fw[s + S_VLIM], fw[s + S_ALIM], fw[s + S_INV_DT]
            acc, minv, corr = iw[I_ACC], iw[I_MINV], iw[I_CORR]
            for k in range(N_ARM):  # τ - c, c = qfrc_bias + J_p,zᵀ m g (the held weight)
                dof = iw[arm + k]
                static = fw[jac + 2 * nv + dof] * gm
                static += mem[bias + dof]
                fw[corr + k] = fw[tau + k] - static
            for k in range(N_ARM):
                fw[acc + k] = mj_dot(fw, minv + 6 * k, fw, corr, N_ARM)
            limited = False
            for k in range(N_ARM):
                a_k = fw[acc + k]
                w_k = mem[qv_arm(iw, k)]
                lo, hi = (-vlim - w_k) * inv_h, (vlim - w_k) * inv_h
                if alim > 0.0:
                    if -alim > lo:
                        lo = -alim
                    if alim < hi:
                        hi = alim
                c = 0.0
                if a_k < lo or a_k > hi:
                    c = (lo if a_k < lo else hi) - a_k
                    limited = True
                fw[corr + k] = c
            if limited:
                return LIMITED
    if phase & CLIP:
        lim, last, ctrl = iw[I_LIMITS], iw[I_LAST], iw[I_CTRL]
        for k in range(N_ARM):
            t = fw[tau + k]
            hi = fw[lim + k]
            lo = -hi
            t = hi if t > hi else t  # np.minimum, then np.maximum (NaN passes through)
            t = lo if t < lo else t
            fw[last + k] = t
            mem[ctrl + iw[act + k]] = t
    return DONE


@kernel
def qv_arm(iw, k):  # type: ignore[no-untyped-def]
    """Offset in MjData's array of arm joint ``k``'s velocity."""
    return iw[I_QVEL] + iw[I_SIZE + iw[I_NCHAIN] + k]
