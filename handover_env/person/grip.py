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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

#: Hand endpoint stiffness (N/m) and viscosity (N s/m), wrist stiffness (N m/rad) and viscosity.
K_ARM = 500.0
B_ARM = 10.0
K_ROT = 5.0
B_ROT = 0.2
_SITE, _BODY = int(mujoco.mjtObj.mjOBJ_SITE), int(mujoco.mjtObj.mjOBJ_BODY)


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


def _rotation_vector(rot: np.ndarray) -> np.ndarray:
    """Axis * angle of a rotation matrix (3,)."""
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, rot.reshape(9))
    if q[0] < 0:
        q = -q
    s = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if s < 1e-12:
        return np.zeros(3)
    return q[1:] * (2.0 * math.atan2(s, q[0]) / s)


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
        self.config = config or GripConfig()
        self._v_site = np.zeros(6)
        self._v_obj = np.zeros(6)
        self.active = False
        self.force = np.zeros(3)
        self.offset_local = np.zeros(3)
        self._rel_rot = np.eye(3)
        # The wrench is applied at every controller tick and held in between: explicit damping is
        # stable while B dt / I < 1, so the rotational damping per axis is capped accordingly.
        self._tick = model.opt.timestep * 3
        self._inertia = model.body_inertia[object_body].copy()
        self._mass = float(model.body_mass[object_body])
        self._rot_damping = np.full(3, self.config.rot_damping)
        self._bound: mujoco.MjData | None = None
        self._rel_w = np.zeros(3)
        self._grasp = np.zeros(3)
        self._grip = np.zeros(3)
        self._neg_force = np.zeros(3)

    def close(self, data: mujoco.MjData, grasp_local: np.ndarray) -> None:
        """Close the hand: hold the object at its point ``grasp_local`` (object frame), keeping
        the object's current orientation relative to the hand."""
        self.offset_local = np.asarray(grasp_local, dtype=np.float64).copy()
        # Transverse inertia about the grasp point (the object's principal axes are its frame's).
        inertia = self._inertia + self._mass * float(self.offset_local @ self.offset_local)
        self._rot_damping = np.minimum(self.config.rot_damping, 0.5 * inertia / self._tick)
        r_hand = data.xmat[self.hand].reshape(3, 3)
        r_obj = data.xmat[self.obj].reshape(3, 3)
        self._rel_rot = r_hand.T @ r_obj
        self.active = True

    def open(self, data: mujoco.MjData) -> None:
        """Let go (removes the grip wrench)."""
        self.active = False
        self.force[:] = 0.0
        data.qfrc_applied[:] = 0.0

    def _bind(self, data: mujoco.MjData) -> None:
        """Views of the ``data`` rows read at every tick (MjData buffers never move)."""
        self._bound = data
        self._r_obj_v = data.xmat[self.obj].reshape(3, 3)
        self._r_hand_v = data.xmat[self.hand].reshape(3, 3)
        self._pos_obj_v = data.xpos[self.obj]
        self._grip_v = data.site_xpos[self.site]
        self._qfrc_v = data.qfrc_applied

    def apply(self, data: mujoco.MjData) -> None:
        """Write this tick's grip wrench into ``data.qfrc_applied`` (call at every tick).

        The 3-vector sums and cross products are plain floats (the same IEEE operations as
        numpy's elementwise ones, at a fraction of the call overhead); the 3x3 products stay
        numpy's, whose rounding they are defined by.
        """
        if not self.active:
            return
        if data is not self._bound:
            self._bind(data)
        m, c = self.model, self.config
        r_obj = self._r_obj_v
        pos = self._pos_obj_v
        arm = r_obj @ self.offset_local
        a0, a1, a2 = arm.tolist()
        p0, p1, p2 = pos.tolist()
        g0, g1, g2 = p0 + a0, p1 + a1, p2 + a2  # the object's grasp point
        v_site, v_obj = self._v_site, self._v_obj
        mujoco.mj_objectVelocity(m, data, _SITE, self.site, v_site, 0)
        mujoco.mj_objectVelocity(m, data, _BODY, self.obj, v_obj, 0)
        # Velocity of the object's grasp point: v_origin + w x (grasp - origin).
        wx, wy, wz, vx, vy, vz = v_obj.tolist()
        d0, d1, d2 = g0 - p0, g1 - p1, g2 - p2
        u0, u1, u2 = vx + (wy * d2 - wz * d1), vy + (wz * d0 - wx * d2), vz + (wx * d1 - wy * d0)
        sx, sy, sz, s0, s1, s2 = v_site.tolist()
        h0, h1, h2 = self._grip_v.tolist()
        k, b = c.stiffness, c.damping
        force = self.force
        force[0] = k * (h0 - g0) + b * (s0 - u0)
        force[1] = k * (h1 - g1) + b * (s1 - u1)
        force[2] = k * (h2 - g2) + b * (s2 - u2)
        r_goal = self._r_hand_v @ self._rel_rot
        # In the object's frame (its z is the bottle's axis): transverse axes only.
        e = r_obj.T @ _rotation_vector(r_goal @ r_obj.T)
        rel_w = self._rel_w
        rel_w[0], rel_w[1], rel_w[2] = sx - wx, sy - wy, sz - wz
        w = r_obj.T @ rel_w
        torque_local = c.rot_stiffness * e + self._rot_damping * w
        torque_local[2] = 0.0
        torque = r_obj @ torque_local
        grasp, grip = self._grasp, self._grip
        grasp[0], grasp[1], grasp[2] = g0, g1, g2
        grip[0], grip[1], grip[2] = h0, h1, h2
        q = self._qfrc_v
        q[:] = 0.0
        mujoco.mj_applyFT(m, data, force, torque, grasp, self.obj, q)
        np.negative(force, out=self._neg_force)
        np.negative(torque, out=torque)
        mujoco.mj_applyFT(m, data, self._neg_force, torque, grip, self.hand, q)
