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
- :data:`CLIP`: τ clipped to the torque limits, kept and written to the arm's ``ctrl``;
- :data:`GATHER` (with ``TORQUE``): first solve the rows ``M^-1 e_arm`` (``minv_rows``, MuJoCo's
  ``mj_solveM`` called from the kernel, :mod:`handover_env.mujoco_calls`) and copy their arm
  columns into the limiter's ``M_arm^-1``.

The products are MuJoCo's (``mju_mulMatVec``, ``mju_mulMatTVec``) in MuJoCo's order
(:func:`handover_env.kernel_math.mj_dot`), so the tick gives the same bits as those calls.
It returns :data:`DONE`, or stops early with :data:`FAR_ROTATION` (orientation error beyond
~120 deg: the caller rescales the rotational wrench, then asks for ``TORQUE | CLIP``) or
:data:`LIMITED` (a joint acceleration out of its bounds: the correction is in the ``corr`` buffer,
the caller applies it, then asks for ``CLIP``). Both are rare; the caller's code for them is
numpy's (a matrix inverse).
"""

from __future__ import annotations

import math

from handover_env.compiled import kernel
from handover_env.kernel_math import fma, mj_dot
from handover_env.lapack_calls import dgesv
from handover_env.mujoco_calls import mj_solve_m, mju_chol_solve

JAC, WRENCH, TORQUE, CLIP, GATHER = 1, 2, 4, 8, 16
ALL = JAC | WRENCH | TORQUE | CLIP
DONE, FAR_ROTATION, LIMITED = 0, 1, 2
SOLVE = -1  # the replan waits for the speed check's solve (impedance_plan, impedance_replan)

# Integer workspace (int64): sizes, offsets in MjData's array and the float workspace, state.
I_NV, I_NCHAIN, I_HAVE_PREV, I_LIMIT = 0, 1, 2, 3
I_XPOS, I_XMAT, I_QVEL, I_CDOF, I_COM, I_BIAS, I_CTRL = 4, 5, 6, 7, 8, 9, 10
I_JAC, I_W, I_Z, I_OUT, I_TAUF, I_TAU, I_POST, I_LIMITS, I_LAST = 11, 12, 13, 14, 15, 16, 17, 18, 19
I_MINV, I_ACC, I_CORR, I_SCAL, I_MINVR = 20, 21, 22, 23, 24
# The replan's buffers (impedance_refresh): J M^-1 (6, nv), Λ^-1 and Λ (6, 6), the gain maps
# P, C and Λ P + C (6, 31), the plan (n, 3, 4), the rotation error maps (36, n).
I_MINVJT, I_LAMINV, I_LAM, I_GAINS, I_PGAIN, I_CGAIN = 25, 26, 27, 28, 29, 30
I_TRAJ, I_ROTMAPS, I_NPLAN = 31, 32, 33
# The plan's (impedance_plan): its state, the filter's powers (n, 3, 3), [1, cos, sin] (3, n), the
# rotation error basis (36, 3), the speed check's arm Jacobian (6, 6) and twists (n, 6).
I_PLAN, I_POWERS, I_CS, I_ROTB, I_JACPLAN, I_TWIST = 34, 35, 36, 37, 38, 39
# MuJoCo's model and data (addresses, for mj_solveM) and the unit rows e_arm (6, nv) in fw.
I_MODEL, I_DATA, I_ARMROWS = 40, 41, 42
# The posture torque's (impedance_posture): qpos in MjData's array, q_rest (6), scratch (18).
I_QPOS, I_REST, I_PTMP = 43, 44, 45
# The replan's solve (plan_solve): its matrix and right-hand sides, column-major (36 + 6 n) in fw,
# and in iw the offset of LAPACK's integers [n, nrhs, lda, ldb, info, ipiv (6)] (L_SIZE).
I_SOLVE, I_LAPACK = 46, 47
I_SIZE = 48  # the fixed slots; then the chain dofs, the 6 arm dofs, the 6 arm actuators and the
# 6 arm joints' qpos addresses, then LAPACK's integers
L_N, L_NRHS, L_LDA, L_LDB, L_INFO, L_IPIV, L_SIZE = 0, 1, 2, 3, 4, 5, 11
# Scalars (float workspace at iw[I_SCAL]): payload weight factor 9.81 m, joint speed limit,
# joint acceleration limit, 1 / tick.
S_GM, S_VLIM, S_ALIM, S_INV_DT, S_DAMP, S_KN, S_DN = 0, 1, 2, 3, 4, 5, 6
S_SIZE = 7
Z_SIZE = 26
B_SIZE = 31  # columns of the gain maps: 16 per-tick, 12 feed-forward, 3 rotation
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
        if phase & GATHER:
            minv, rows = iw[I_MINV], iw[I_MINVR]
            base = fw.ctypes.data
            mj_solve_m(iw[I_MODEL], iw[I_DATA], base + 8 * rows, base + 8 * iw[I_ARMROWS], N_ARM)
            for r in range(N_ARM):
                for c in range(N_ARM):
                    fw[minv + N_ARM * r + c] = fw[rows + r * nv + iw[arm + c]]
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


@kernel
def impedance_refresh(fw, iw):  # type: ignore[no-untyped-def]
    """The replan's ``J M^-1`` (MuJoCo's ``mj_solveM`` on this tick's J), Λ and W_k.

    ``Λ^-1 = J M^-1 Jᵀ + d I`` (MuJoCo's ``mju_mulMatMatT``), factored in place as MuJoCo's
    ``mju_cholFactor`` does, ``Λ`` row by row with ``mju_cholSolve``; then ``B = Λ P + C`` and
    the plan's matrices ``W_k`` (the per-tick columns of B, its feed-forward rows times the plan
    and its rotation rows times the rotation error maps), each product summed as numpy's
    ``matmul`` sums it (a fused multiply-add chain, :func:`handover_env.kernel_math.fma`).
    """
    nv, n = iw[I_NV], iw[I_NPLAN]
    jac, mjt, li, lam = iw[I_JAC], iw[I_MINVJT], iw[I_LAMINV], iw[I_LAM]
    base = fw.ctypes.data
    mj_solve_m(iw[I_MODEL], iw[I_DATA], base + 8 * mjt, base + 8 * jac, 6)  # rows of J M^-1
    damp = fw[iw[I_SCAL] + S_DAMP]
    for r in range(6):
        for c in range(6):
            v = mj_dot(fw, mjt + r * nv, fw, jac + c * nv, nv)
            fw[li + 6 * r + c] = v + (damp if r == c else 0.0)
    for j in range(6):  # mju_cholFactor(Λ^-1, 0)
        t = fw[li + 7 * j]
        if j:
            t -= mj_dot(fw, li + 6 * j, fw, li + 6 * j, j)
        deficient = t < 0.0
        if deficient:
            t = 0.0
        fw[li + 7 * j] = math.sqrt(t)
        if deficient:
            for i in range(j + 1, 6):
                fw[li + 6 * i + j] = 0.0
        else:
            t = 1.0 / fw[li + 7 * j]
            for i in range(j + 1, 6):
                fw[li + 6 * i + j] = (fw[li + 6 * i + j]
                                      - mj_dot(fw, li + 6 * i, fw, li + 6 * j, j)) * t
    for k in range(6):  # Λ e_k by mju_cholSolve (Λ is symmetric: rows = columns)
        row = lam + 6 * k
        for i in range(6):
            fw[row + i] = 1.0 if i == k else 0.0
        for i in range(6):
            if i:
                fw[row + i] -= mj_dot(fw, li + 6 * i, fw, row, i)
            fw[row + i] /= fw[li + 7 * i]
        for i in range(5, -1, -1):
            if i < 5:
                for j in range(i + 1, 6):
                    fw[row + i] -= fw[li + 6 * j + i] * fw[row + j]
            fw[row + i] /= fw[li + 7 * i]
    b, p, cg = iw[I_GAINS], iw[I_PGAIN], iw[I_CGAIN]
    for r in range(6):  # B = Λ P + C
        for c in range(B_SIZE):
            acc = fw[lam + 6 * r] * fw[p + c]
            for k in range(1, 6):
                acc = fma(fw[lam + 6 * r + k], fw[p + B_SIZE * k + c], acc)
            fw[b + B_SIZE * r + c] = acc + fw[cg + B_SIZE * r + c]
    w, traj, rm = iw[I_W], iw[I_TRAJ], iw[I_ROTMAPS]
    for k in range(n):
        for r in range(6):
            wr = w + (7 * k + r) * Z_SIZE
            for c in range(16):  # the per-tick columns
                fw[wr + c] = fw[b + B_SIZE * r + c]
            acc = fw[b + B_SIZE * r + 16] * fw[traj + 12 * k]  # feed-forward: B_ff plan_k
            for m in range(1, 12):
                acc = fma(fw[b + B_SIZE * r + 16 + m], fw[traj + 12 * k + m], acc)
            fw[wr + 16] = acc
            for c in range(9):  # rotation: B_rot L_k, L_k = rot_maps[9 a + c, k]
                acc = fw[b + B_SIZE * r + 28] * fw[rm + c * n + k]
                for a in range(1, 3):
                    acc = fma(fw[b + B_SIZE * r + 28 + a], fw[rm + (9 * a + c) * n + k], acc)
                fw[wr + 17 + c] = acc


# The plan's state (float workspace at iw[I_PLAN]): the reference's start, velocity, yaw and yaw
# rate, the filter's target and the goal, the goal's yaw, the largest step, the filter's input
# s0 (3, 4) and the speed check's J Jᵀ + d I (6, 6).
P_X, P_V, P_YAW, P_YAW_RATE, P_TARGET, P_GOAL, P_GOAL_YAW, P_MAX_STEP = 0, 3, 6, 7, 8, 11, 14, 15
P_S0, P_JJT, P_SIZE = 16, 28, 64


@kernel
def _mul_mat_mat(fw, res, a, b, r1, c1, c2):  # type: ignore[no-untyped-def]
    """``res = a @ b`` in the workspace, as MuJoCo's ``mju_mulMatMat`` sums it (zero entries
    of ``a`` skipped)."""
    for i in range(r1):
        for j in range(c2):
            fw[res + i * c2 + j] = 0.0
        for k in range(c1):
            t = fw[a + i * c1 + k]
            if t != 0.0:
                for j in range(c2):
                    fw[res + i * c2 + j] += fw[b + k * c2 + j] * t


@kernel
def _plan_finish(fw, iw):  # type: ignore[no-untyped-def]
    """The plan's rotation error maps (``[1, cos ψ_k, sin ψ_k]`` times the basis) and the trace
    row of every W_k."""
    n, traj, cs, rm, w = iw[I_NPLAN], iw[I_TRAJ], iw[I_CS], iw[I_ROTMAPS], iw[I_W]
    for k in range(n):
        yaw = fw[traj + 12 * k + 3]
        fw[cs + k] = 1.0
        fw[cs + n + k] = math.cos(yaw)
        fw[cs + 2 * n + k] = math.sin(yaw)
    _mul_mat_mat(fw, rm, iw[I_ROTB], cs, 36, 3, n)
    for k in range(n):
        for c in range(9):
            fw[w + (7 * k + 6) * Z_SIZE + 17 + c] = fw[rm + (27 + c) * n + k]


@kernel
def impedance_plan(mem, fw, iw, last, check_speed):  # type: ignore[no-untyped-def]
    """Plan the reference filter's next ticks from the state reached at planned tick ``last``
    (-1: the start); see ``ImpedanceController._plan``. With ``check_speed`` it leaves the
    speed check's ``J Jᵀ + d I`` and the plan's twists in the workspace and returns
    :data:`SOLVE` (the solve and :func:`impedance_plan_scale` follow); else it finishes the plan
    and returns 0.
    """
    n, traj, p = iw[I_NPLAN], iw[I_TRAJ], iw[I_PLAN]
    if last >= 0:  # the reference state reached by the last tick of the current plan
        row = traj + 12 * last
        for k in range(3):
            fw[p + P_X + k] = fw[row + k]
            fw[p + P_V + k] = fw[row + 4 + k]
        fw[p + P_YAW] = fw[row + 3]
        fw[p + P_YAW_RATE] = fw[row + 7]
    x0, x1, x2 = fw[p + P_X], fw[p + P_X + 1], fw[p + P_X + 2]
    d0, d1, d2 = fw[p + P_GOAL] - x0, fw[p + P_GOAL + 1] - x1, fw[p + P_GOAL + 2] - x2
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    max_step = fw[p + P_MAX_STEP]
    if dist > max_step:
        f = max_step / dist
        d0, d1, d2 = d0 * f, d1 * f, d2 * f
    t0, t1, t2 = x0 + d0, x1 + d1, x2 + d2
    fw[p + P_TARGET], fw[p + P_TARGET + 1], fw[p + P_TARGET + 2] = t0, t1, t2
    # The yaw goes through the same filter, along the shorter way round.
    yaw_t = fw[p + P_GOAL_YAW]
    dyaw = (fw[p + P_YAW] - yaw_t + math.pi) % (2 * math.pi) - math.pi
    s0 = p + P_S0
    fw[s0], fw[s0 + 1], fw[s0 + 2], fw[s0 + 3] = x0 - t0, x1 - t1, x2 - t2, dyaw
    for k in range(3):
        fw[s0 + 4 + k] = fw[p + P_V + k]
    fw[s0 + 7] = fw[p + P_YAW_RATE]
    fw[s0 + 8], fw[s0 + 9], fw[s0 + 10], fw[s0 + 11] = t0, t1, t2, yaw_t
    _mul_mat_mat(fw, traj, iw[I_POWERS], s0, 3 * n, 3, 4)  # (n, 3: x_d, v, a; 4: x, y, z, ψ)
    if not check_speed:
        _plan_finish(fw, iw)
        return 0
    # The speed check's Jacobian (mj_jac's formula on this state), arm columns only.
    nchain = iw[I_NCHAIN]
    arm = I_SIZE + nchain
    xp, com, cdof = iw[I_XPOS], iw[I_COM], iw[I_CDOF]
    jp = iw[I_JACPLAN]
    o0 = mem[xp] - mem[com]
    o1 = mem[xp + 1] - mem[com + 1]
    o2 = mem[xp + 2] - mem[com + 2]
    for c in range(N_ARM):
        d = cdof + 6 * iw[arm + c]
        a0, a1, a2 = mem[d], mem[d + 1], mem[d + 2]
        fw[jp + c] = mem[d + 3] + (a1 * o2 - a2 * o1)
        fw[jp + 6 + c] = mem[d + 4] + (a2 * o0 - a0 * o2)
        fw[jp + 12 + c] = mem[d + 5] + (a0 * o1 - a1 * o0)
        fw[jp + 18 + c], fw[jp + 24 + c], fw[jp + 30 + c] = a0, a1, a2
    jjt = p + P_JJT
    damp = fw[iw[I_SCAL] + S_DAMP]
    for r in range(6):  # J Jᵀ as numpy's matmul sums it, then + d on the diagonal
        for c in range(6):
            acc = fw[jp + 6 * r] * fw[jp + 6 * c]
            for k in range(1, 6):
                acc = fma(fw[jp + 6 * r + k], fw[jp + 6 * c + k], acc)
            fw[jjt + 6 * r + c] = acc + damp if r == c else acc
    tw = iw[I_TWIST]  # (n, 6): [v_d, 0, 0, ψ̇_d] at each planned tick
    for k in range(n):
        for c in range(3):
            fw[tw + 6 * k + c] = fw[traj + 12 * k + 4 + c]
        fw[tw + 6 * k + 5] = fw[traj + 12 * k + 7]
    return SOLVE


@kernel
def impedance_plan_scale(fw, iw, sol):  # type: ignore[no-untyped-def]
    """The speed check after the caller's solve ``sol = (J Jᵀ + d I)^-1 twistᵀ`` (6, n): the
    joint velocities ``q̇ = Jᵀ sol``, and if their largest magnitude exceeds the limit the plan
    slowed by ``q̇_max / peak``; then the plan is finished. Returns 1 if it was slowed."""
    n, traj, p, jp = iw[I_NPLAN], iw[I_TRAJ], iw[I_PLAN], iw[I_JACPLAN]
    peak = -1.0
    for r in range(6):
        for c in range(n):
            acc = fw[jp + r] * sol[0, c]
            for k in range(1, 6):
                acc = fma(fw[jp + 6 * k + r], sol[k, c], acc)
            a = abs(acc)
            if a > peak or a != a:  # np.max: a NaN wins
                if peak == peak:
                    peak = a
    vlim = fw[iw[I_SCAL] + S_VLIM]
    scaled = 0
    if peak > vlim:
        scale = vlim / peak
        if scale < 1.0:  # the same plan, slowed: its displacement and velocities times scale
            s0 = p + P_S0
            for k in range(8):
                fw[s0 + k] *= scale
            t0 = fw[p + P_X] - fw[s0]
            t1 = fw[p + P_X + 1] - fw[s0 + 1]
            t2 = fw[p + P_X + 2] - fw[s0 + 2]
            fw[s0 + 8], fw[s0 + 9], fw[s0 + 10] = t0, t1, t2
            fw[s0 + 11] = fw[p + P_YAW] - fw[s0 + 3]
            fw[p + P_TARGET], fw[p + P_TARGET + 1], fw[p + P_TARGET + 2] = t0, t1, t2
            _mul_mat_mat(fw, traj, iw[I_POWERS], s0, 3 * n, 3, 4)
            scaled = 1
    _plan_finish(fw, iw)
    return scaled


# The solve and the whole replan in one call exist where numpy's LAPACK was found
# (:mod:`handover_env.lapack_calls`); else they are None and the controller calls
# impedance_plan, numpy's solve and impedance_plan_scale.
if dgesv is not None:

    @kernel
    def plan_solve(fw, iw):  # type: ignore[no-untyped-def]
        """The speed check's ``sol = (J Jᵀ + d I)^-1 twistᵀ`` (6, n) by numpy's own ``dgesv``,
        called as ``numpy.linalg.solve`` calls it: on column-major copies of the matrix and of
        the right-hand sides (the (n, 6) twists, row-major, are the (6, n) right-hand sides
        column-major), in one buffer at ``iw[I_SOLVE]`` (matrix, then the right-hand sides, which
        hold the solution afterwards). Returns LAPACK's ``info`` (> 0: singular)."""
        n, a, li = iw[I_NPLAN], iw[I_SOLVE], iw[I_LAPACK]
        jjt, tw = iw[I_PLAN] + P_JJT, iw[I_TWIST]
        b = a + 36
        for r in range(6):
            for c in range(6):
                fw[a + 6 * c + r] = fw[jjt + 6 * r + c]
        for k in range(6 * n):
            fw[b + k] = fw[tw + k]
        iw[li + L_N], iw[li + L_NRHS], iw[li + L_LDA], iw[li + L_LDB] = 6, n, 6, 6
        iw[li + L_INFO] = 0
        fp, ip = fw.ctypes.data, iw.ctypes.data + 8 * li
        dgesv(ip + 8 * L_N, ip + 8 * L_NRHS, fp + 8 * a, ip + 8 * L_LDA, ip + 8 * L_IPIV,
              fp + 8 * b, ip + 8 * L_LDB, ip + 8 * L_INFO)
        return iw[li + L_INFO]

    @kernel
    def impedance_replan(mem, fw, iw, last, check_speed):  # type: ignore[no-untyped-def]
        """The whole replan: :func:`impedance_plan`, with ``check_speed`` the solve
        (:func:`plan_solve`) and :func:`impedance_plan_scale`. Returns 1 if the plan was slowed,
        0 if not, :data:`SOLVE` if the damped system is singular (the plan then waits, as after
        :func:`impedance_plan`, for the caller's solve: numpy's raises ``LinAlgError``)."""
        if impedance_plan(mem, fw, iw, last, check_speed) == 0:
            return 0
        if plan_solve(fw, iw) != 0:
            return SOLVE
        n, b = iw[I_NPLAN], iw[I_SOLVE] + 36
        return impedance_plan_scale(fw, iw, fw[b:b + 6 * n].reshape((n, 6)).T)

else:
    plan_solve = impedance_replan = None


@kernel
def impedance_posture(mem, fw, iw):  # type: ignore[no-untyped-def]
    """The null-space posture torque ``N τ_0 = τ_0 - Jᵀ Λ J M^-1 τ_0``, τ_0 = k_n (q_rest - q) -
    d_n q̇ (arm joints), after :func:`impedance_refresh` (J M^-1, Λ^-1's Cholesky factor).

    ``J M^-1 τ_0`` and ``(Λ ·)ᵀ J`` over the arm columns are summed as numpy's ``dot`` sums a
    (6, 6) strided matrix times a vector and a vector times one (OpenBLAS's dgemv_t and dgemv_n
    kernels: products of four lanes added pairwise, the last two as one fused multiply-add; and
    for the first four outputs ``fma(a2, x2, a0 x0) + fma(a3, x3, a1 x1) + (a4 x4 + a5 x5)``, the
    last two a plain running sum); the solve is MuJoCo's ``mju_cholSolve``.
    """
    nv, nc = iw[I_NV], iw[I_NCHAIN]
    s, post, mjt, jac = iw[I_SCAL], iw[I_POST], iw[I_MINVJT], iw[I_JAC]
    kn, dn = fw[s + S_KN], fw[s + S_DN]
    rest, t0, y, z = iw[I_REST], iw[I_PTMP], iw[I_PTMP] + 6, iw[I_PTMP] + 12
    arm = I_SIZE + nc
    for k in range(N_ARM):
        q = mem[iw[I_QPOS] + iw[arm + 12 + k]]
        fw[t0 + k] = (fw[rest + k] - q) * kn - mem[iw[I_QVEL] + iw[arm + k]] * dn
    for r in range(N_ARM):  # y = (J M^-1)_arm τ_0
        row = mjt + r * nv
        a0, a1, a2 = fw[row + iw[arm]], fw[row + iw[arm + 1]], fw[row + iw[arm + 2]]
        a3, a4, a5 = fw[row + iw[arm + 3]], fw[row + iw[arm + 4]], fw[row + iw[arm + 5]]
        main = (a0 * fw[t0] + a2 * fw[t0 + 2]) + (a1 * fw[t0 + 1] + a3 * fw[t0 + 3])
        fw[y + r] = (0.0 + main) + fma(a4, fw[t0 + 4], a5 * fw[t0 + 5])
    base = fw.ctypes.data
    mju_chol_solve(base + 8 * z, base + 8 * iw[I_LAMINV], base + 8 * y, N_ARM)  # Λ y
    for c in range(N_ARM):  # (Λ y)ᵀ J_arm
        dof = iw[arm + c]
        p0 = fw[jac + dof] * fw[z]
        p1 = fw[jac + nv + dof] * fw[z + 1]
        p2 = fw[jac + 2 * nv + dof] * fw[z + 2]
        p3 = fw[jac + 3 * nv + dof] * fw[z + 3]
        p4 = fw[jac + 4 * nv + dof] * fw[z + 4]
        p5 = fw[jac + 5 * nv + dof] * fw[z + 5]
        if c < 4:
            v = (fma(fw[jac + 2 * nv + dof], fw[z + 2], p0)
                 + fma(fw[jac + 3 * nv + dof], fw[z + 3], p1)) + (p4 + p5)
        else:
            v = (((((0.0 + p0) + p1) + p2) + p3) + p4) + p5
        fw[post + c] = fw[t0 + c] - v
