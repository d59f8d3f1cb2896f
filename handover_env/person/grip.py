"""How the person holds the object: the arm as a spring-damper between the hand and the object.

Once the hand has closed on the object, the person holds it through their arm, which is not rigid:
a held hand yields like a spring around where the person means it to be. :class:`ArmGrip` applies
that coupling explicitly, at every 200 Hz controller tick, as equal and opposite wrenches on the
object (at its grasp point) and on the hand (at its grip point):

    F = K_arm (p_grip - p_grasp) + B_arm (v_grip - v_grasp)
    tau = K_rot e + B_rot (w_hand - w_object)

with e the rotation vector taking the object's orientation to the one it had in the hand at the
grasp, about the object's two transverse axes (a bottle spinning about its own axis in the hand
does not matter to the handover, and that axis's tiny inertia would make the explicit coupling
unstable). The translational stiffness and damping are the human hand's endpoint impedance in a
relaxed posture (Mussa-Ivaldi, Hogan & Bizzi 1985: 300-800 N/m; Tsuji et al. 1995: viscosity
5-15 N s/m); the rotational ones are the wrist's (Formica et al. 2012: about 1-10 N m/rad).
So the pull on the robot builds up as the person walks on while the robot still holds the object:
the wrist F/T sensor measures exactly this force, and the gripper opens when it exceeds f_r.

The hand's own pose follows the person's motion (a stiff weld, see
:mod:`handover_env.person.body_model`); the grip spring is the only coupling between the person
and the object, so the force the person exerts (``pull``) is known exactly.

The tick is one compiled call (:func:`grip_kernel`): the velocities, the rotation's quaternion and
the wrenches' joint forces by MuJoCo's own functions (``mj_objectVelocity``, ``mju_mat2Quat``,
``mj_applyFT``, :mod:`handover_env.mujoco_calls`), the 3x3 products in numpy's matmul order
(:mod:`handover_env.kernel_math`), the rest as the formulas above read, left to right.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from handover_env.compiled import kernel
from handover_env.kernel_math import mat3_mul, mat3_vec, mat3t_vec
from handover_env.mjdata_view import MjDataView
from handover_env.mujoco_calls import mj_apply_ft, mj_object_velocity, mju_mat2quat

#: Hand endpoint stiffness (N/m) and viscosity (N s/m), wrist stiffness (N m/rad) and viscosity.
K_ARM = 500.0
B_ARM = 10.0
K_ROT = 5.0
B_ROT = 0.2
_SITE, _BODY = int(mujoco.mjtObj.mjOBJ_SITE), int(mujoco.mjtObj.mjOBJ_BODY)

# The grip's float64 state (offsets): the grasp point in the object's frame, the object's
# rotation relative to the hand at the grasp (3x3, row-major), the rotational damping per axis,
# K, B, K_rot, the force on the object (read as ArmGrip.force), then the tick's scratch: site and
# object velocities, quaternion, R_goal, R_goal R_objᵀ, torque, the negated wrench, the points.
G_OFF, G_REL, G_RD, G_K, G_B, G_KR, G_FORCE = 0, 3, 12, 15, 16, 17, 18
G_VSITE, G_VOBJ, G_QUAT, G_RGOAL, G_RREL, G_TORQUE = 21, 27, 33, 37, 46, 55
G_NFORCE, G_NTORQUE, G_GRASP, G_GRIP, G_SIZE = 58, 61, 64, 67, 70
# Its int64 state: model and data addresses, ids, offsets in MjDataView.mem, nv.
I_MODEL, I_DATA, I_SITE, I_OBJ, I_HAND = 0, 1, 2, 3, 4
I_XMAT_OBJ, I_XMAT_HAND, I_XPOS_OBJ, I_GRIP, I_QFRC, I_NV, I_SIZE = 5, 6, 7, 8, 9, 10, 11


@dataclass(frozen=True)
class GripConfig:
    """Impedance of the holding arm (see the module docstring for the sources)."""

    stiffness: float = K_ARM
    damping: float = B_ARM
    rot_stiffness: float = K_ROT
    rot_damping: float = B_ROT

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"GripConfig.{name} must be finite and >= 0, got {value}")


@kernel
def grip_kernel(mem, gs, gi):  # type: ignore[no-untyped-def]
    """One tick of the grip: writes the wrench's joint forces to ``qfrc_applied`` (zeroed first)
    and the force on the object to ``gs[G_FORCE:G_FORCE+3]``; ``mem`` is MjDataView.mem."""
    m, d = gi[I_MODEL], gi[I_DATA]
    ro, po, gp, qf = gi[I_XMAT_OBJ], gi[I_XPOS_OBJ], gi[I_GRIP], gi[I_QFRC]
    base = gs.ctypes.data
    a0, a1, a2 = mat3_vec(mem, ro, gs[G_OFF], gs[G_OFF + 1], gs[G_OFF + 2])  # R_obj offset
    p0, p1, p2 = mem[po], mem[po + 1], mem[po + 2]
    g0, g1, g2 = p0 + a0, p1 + a1, p2 + a2  # the object's grasp point
    mj_object_velocity(m, d, _SITE, gi[I_SITE], base + 8 * G_VSITE, 0)
    mj_object_velocity(m, d, _BODY, gi[I_OBJ], base + 8 * G_VOBJ, 0)
    # Velocity of the object's grasp point: v_origin + w x (grasp - origin).
    wx, wy, wz = gs[G_VOBJ], gs[G_VOBJ + 1], gs[G_VOBJ + 2]
    vx, vy, vz = gs[G_VOBJ + 3], gs[G_VOBJ + 4], gs[G_VOBJ + 5]
    d0, d1, d2 = g0 - p0, g1 - p1, g2 - p2
    u0, u1, u2 = vx + (wy * d2 - wz * d1), vy + (wz * d0 - wx * d2), vz + (wx * d1 - wy * d0)
    sx, sy, sz = gs[G_VSITE], gs[G_VSITE + 1], gs[G_VSITE + 2]
    s0, s1, s2 = gs[G_VSITE + 3], gs[G_VSITE + 4], gs[G_VSITE + 5]
    h0, h1, h2 = mem[gp], mem[gp + 1], mem[gp + 2]
    k, b = gs[G_K], gs[G_B]
    gs[G_FORCE] = k * (h0 - g0) + b * (s0 - u0)
    gs[G_FORCE + 1] = k * (h1 - g1) + b * (s1 - u1)
    gs[G_FORCE + 2] = k * (h2 - g2) + b * (s2 - u2)
    mat3_mul(gs, G_RGOAL, mem, gi[I_XMAT_HAND], gs, G_REL, False)  # R_hand R_rel
    mat3_mul(gs, G_RREL, gs, G_RGOAL, mem, ro, True)  # R_goal R_objᵀ
    # its rotation vector (axis * angle), from MuJoCo's quaternion with w >= 0
    mju_mat2quat(base + 8 * G_QUAT, base + 8 * G_RREL)
    q0, q1, q2, q3 = gs[G_QUAT], gs[G_QUAT + 1], gs[G_QUAT + 2], gs[G_QUAT + 3]
    if q0 < 0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    s = math.sqrt(q1 * q1 + q2 * q2 + q3 * q3)
    r0, r1, r2 = 0.0, 0.0, 0.0
    if not s < 1e-12:
        f = 2.0 * math.atan2(s, q0) / s
        r0, r1, r2 = q1 * f, q2 * f, q3 * f
    # In the object's frame (its z is the bottle's axis): transverse axes only.
    e0, e1, e2 = mat3t_vec(mem, ro, r0, r1, r2)
    w0, w1, w2 = mat3t_vec(mem, ro, sx - wx, sy - wy, sz - wz)
    kr = gs[G_KR]
    t0 = kr * e0 + gs[G_RD] * w0
    t1 = kr * e1 + gs[G_RD + 1] * w1
    tx, ty, tz = mat3_vec(mem, ro, t0, t1, 0.0)
    gs[G_TORQUE], gs[G_TORQUE + 1], gs[G_TORQUE + 2] = tx, ty, tz
    gs[G_GRASP], gs[G_GRASP + 1], gs[G_GRASP + 2] = g0, g1, g2
    gs[G_GRIP], gs[G_GRIP + 1], gs[G_GRIP + 2] = h0, h1, h2
    for i in range(3):
        gs[G_NFORCE + i] = -gs[G_FORCE + i]
        gs[G_NTORQUE + i] = -gs[G_TORQUE + i]
    for i in range(gi[I_NV]):
        mem[qf + i] = 0.0
    qfrc = mem.ctypes.data + 8 * qf
    mj_apply_ft(m, d, base + 8 * G_FORCE, base + 8 * G_TORQUE, base + 8 * G_GRASP, gi[I_OBJ],
                qfrc)
    mj_apply_ft(m, d, base + 8 * G_NFORCE, base + 8 * G_NTORQUE, base + 8 * G_GRIP,
                gi[I_HAND], qfrc)


class ArmGrip:
    """The spring-damper grip between the person's hand and the object.

    Args:
        model: the compiled scene.
        hand_body: the hand segment's body id.
        grip_site: the hand's grip point (site id).
        object_body: the object's body id.
        config: the arm's impedance.
    """

    def __init__(self, model: mujoco.MjModel, hand_body: int, grip_site: int, object_body: int,
                 config: GripConfig | None = None) -> None:
        self.model = model
        self.hand, self.site, self.obj = hand_body, grip_site, object_body
        for name, i, n in (("hand_body", hand_body, model.nbody), ("grip_site", grip_site,
                           model.nsite), ("object_body", object_body, model.nbody)):
            if not 0 <= int(i) < n:
                raise ValueError(f"{name} must be an id in [0, {n}), got {i}")
        self.config = c = config or GripConfig()
        self.state = gs = np.zeros(G_SIZE)
        self._ids = np.zeros(I_SIZE, dtype=np.int64)
        self.active = False
        self.force = gs[G_FORCE:G_FORCE + 3]
        self.offset_local = gs[G_OFF:G_OFF + 3]
        self._rel_rot = gs[G_REL:G_REL + 9].reshape(3, 3)
        self._rel_rot[...] = np.eye(3)
        gs[G_K], gs[G_B], gs[G_KR] = c.stiffness, c.damping, c.rot_stiffness
        # The wrench is applied at every controller tick and held in between: explicit damping is
        # stable while B dt / I < 1, so the rotational damping per axis is capped accordingly.
        self._tick = model.opt.timestep * 3
        self._inertia = model.body_inertia[object_body].copy()
        self._mass = float(model.body_mass[object_body])
        self._rot_damping = gs[G_RD:G_RD + 3]
        self._rot_damping[:] = c.rot_damping
        self._bound: mujoco.MjData | None = None

    def close(self, data: mujoco.MjData, grasp_local: np.ndarray) -> None:
        """Close the hand: hold the object at its point ``grasp_local`` (object frame), keeping
        the object's current orientation relative to the hand."""
        self.offset_local[:] = np.asarray(grasp_local, dtype=np.float64)
        # Transverse inertia about the grasp point (the object's principal axes are its frame's).
        inertia = self._inertia + self._mass * float(self.offset_local @ self.offset_local)
        self._rot_damping[:] = np.minimum(self.config.rot_damping, 0.5 * inertia / self._tick)
        r_hand = data.xmat[self.hand].reshape(3, 3)
        r_obj = data.xmat[self.obj].reshape(3, 3)
        self._rel_rot[...] = r_hand.T @ r_obj
        self.active = True

    def open(self, data: mujoco.MjData) -> None:
        """Let go (removes the grip wrench)."""
        self.active = False
        self.force[:] = 0.0
        data.qfrc_applied[:] = 0.0

    def _bind(self, data: mujoco.MjData) -> None:
        """The kernel's addresses and offsets for ``data`` (MjData buffers never move)."""
        if data.qfrc_applied.shape[0] != self.model.nv:
            raise ValueError("data is not an MjData of this grip's model")
        view = self._view = MjDataView(data)
        gi = self._ids
        gi[I_MODEL], gi[I_DATA] = self.model._address, data._address
        gi[I_SITE], gi[I_OBJ], gi[I_HAND] = self.site, self.obj, self.hand
        gi[I_XMAT_OBJ] = view.offset("xmat", self.obj)
        gi[I_XMAT_HAND] = view.offset("xmat", self.hand)
        gi[I_XPOS_OBJ] = view.offset("xpos", self.obj)
        gi[I_GRIP] = view.offset("site_xpos", self.site)
        gi[I_QFRC], gi[I_NV] = view.offset("qfrc_applied"), self.model.nv
        self._bound = data

    def apply(self, data: mujoco.MjData) -> None:
        """Write this tick's grip wrench into ``data.qfrc_applied`` (call at every tick;
        :func:`grip_kernel`)."""
        if not self.active:
            return
        if data is not self._bound:
            self._bind(data)
        grip_kernel(self._view.mem, self.state, self._ids)
