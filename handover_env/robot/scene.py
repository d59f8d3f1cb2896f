"""Build the handover scene with ``MjSpec``: Menagerie UR5e + Robotiq 2F-85 + object + receiver.

* The world (floor, pedestal, object, receiver mocap bodies, cameras) is our own MJCF,
  ``handover_env/assets/scene.xml``.
* The UR5e (``universal_robots_ur5e/ur5e.xml``) and the 2F-85 (``robotiq_2f85/2f85.xml``) are the
  unmodified Menagerie files (see :mod:`handover_env.robot.menagerie`). The gripper is attached to
  the UR5e ``attachment_site`` with ``MjSpec.attach``; the arm is attached to the pedestal's
  ``robot_mount`` site at (0, -0.2, 0.79), the base position of the public dataset's own robot
  replay, turned by ``base_yaw``.
* What we change in the compiled model, not in the files: the six UR5e position servos become
  torque motors (gain 1, no bias) whose ``ctrlrange`` is the UR5e torque limit (150 N*m for
  joints 1-3, 28 N*m for joints 4-6), because the Cartesian impedance controller commands torque.
* A wrist force/torque sensor: a site on the gripper's ``base_mount`` (the flange side of the
  gripper) with ``force``, ``torque`` and ``accelerometer`` sensors. MuJoCo reports the force the
  gripper subtree (plus whatever it holds) exerts on the flange, in the site frame.
* The robot's grasp is a weld equality, ``gripper_grasp`` (2F-85 pads <-> object), switched at
  runtime through ``data.eq_active`` (see :mod:`handover_env.envs.base_handover` for why). The
  person holds the object through their compliant arm (:mod:`handover_env.person.grip`).

Base yaw: the dataset's handovers happen at x 0..0.5, y -0.3..-0.8, z 1.0..1.36, i.e. beside the
base toward -y (where the receiver walks past) and slightly +x (where the receiver comes from).
``base_yaw = -pi/2`` turns the UR5e so that its home configuration faces that side. With the
gripper pointing toward the receiver's path (yaw about -pi/2), the arm reaches the whole box
except the column right against the pedestal (x ~ 0, y > -0.6), where the wrist would sit on the
base axis (the UR shoulder singularity); ``tests/env/test_controller.py`` checks the corners.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

from handover_env.person.body_model import GEOM_NAMES, BodyIds, add_receiver, body_ids
from handover_env.person.body_model import PREFIX as RECEIVER_PREFIX
from handover_env.person.receiver import ReceiverIds
from handover_env.robot.menagerie import robotiq_2f85_xml, ur5e_xml

ASSETS = Path(__file__).resolve().parents[1] / "assets"
ROBOT_BASE = (0.0, -0.2, 0.79)
ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
TORQUE_LIMITS = np.array([150.0, 150.0, 150.0, 28.0, 28.0, 28.0])
ARM_PREFIX = "ur5e/"
GRIPPER_PREFIX = "gripper/"
GRIPPER_CLOSED_CTRL = 255.0
GRIPPER_OPEN_CTRL = 0.0
# Collision bitmasks (see assets/scene.xml): the robot touches only the receiver.
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 1, 2


@dataclass(frozen=True)
class SceneConfig:
    """How the scene is built.

    Args:
        base_yaw: yaw of the UR5e base on its pedestal, rad (see the module docstring).
        timestep: physics step, s (1/600 s: 3 steps per 200 Hz controller tick).
        object_mass: mass of the handed-over object, kg (bottle-sized, 0.3-0.5 kg).
    """

    base_yaw: float = -math.pi / 2
    timestep: float = 1.0 / 600.0
    object_mass: float = 0.4

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.base_yaw, self.timestep, self.object_mass)):
            raise ValueError("SceneConfig values must be finite")
        if not 0 < self.timestep <= 0.005:
            raise ValueError(f"timestep must be in (0, 0.005] s, got {self.timestep}")
        if not 0.05 <= self.object_mass <= 2.0:
            raise ValueError(f"object_mass must be in [0.05, 2] kg, got {self.object_mass}")


@dataclass
class SceneIds:
    """Indices into the compiled model, looked up once (no name lookups in the hot path)."""

    arm_qpos: np.ndarray
    arm_dof: np.ndarray
    arm_act: np.ndarray
    gripper_act: int
    gripper_driver_qpos: int
    tcp_site: int
    ft_site: int
    ft_force_adr: int
    ft_torque_adr: int
    ft_acc_adr: int
    gripper_root_body: int
    object_body: int
    object_qpos: int
    object_dof: int
    object_geom: int
    body: BodyIds
    eq_gripper: int
    robot_geoms: np.ndarray
    receiver_geoms: np.ndarray
    receiver_geom_names: tuple[str, ...]
    payload_mass: float = 0.0
    payload_com_local: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def receiver(self) -> ReceiverIds:
        """What the receiver reads of the scene: its body's indices and the object's body."""
        return ReceiverIds(body=self.body, object_body=self.object_body)


def _motorize(arm: mujoco.MjSpec) -> None:
    """Turn the Menagerie UR5e position servos into torque motors limited to the UR5e ratings."""
    for act, limit in zip(arm.actuators, TORQUE_LIMITS):
        act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        act.biastype = mujoco.mjtBias.mjBIAS_NONE
        act.gainprm = np.r_[1.0, np.zeros(9)]
        act.biasprm = np.zeros(10)
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = np.array([-limit, limit])
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = np.array([-limit, limit])


def build_spec(config: SceneConfig | None = None) -> mujoco.MjSpec:
    """The full scene as an editable ``MjSpec`` (compile it with ``spec.compile()``)."""
    config = config or SceneConfig()
    world = mujoco.MjSpec.from_file(str(ASSETS / "scene.xml"))
    world.option.timestep = config.timestep
    arm = mujoco.MjSpec.from_file(str(ur5e_xml()))
    gripper = mujoco.MjSpec.from_file(str(robotiq_2f85_xml()))
    _motorize(arm)
    arm.option.cone, arm.option.impratio = gripper.option.cone, gripper.option.impratio

    # Wrist F/T sensor: a site on the gripper's mounting plate, i.e. between flange and gripper.
    mount = gripper.body("base_mount")
    mount.add_site(name="ft_site", pos=[0, 0, 0], size=[0.01, 0.01, 0.01], group=4)
    # Tool centre point: the Menagerie "pinch" site between the finger pads.
    gripper.add_sensor(name="ft_force", type=mujoco.mjtSensor.mjSENS_FORCE,
                       objtype=mujoco.mjtObj.mjOBJ_SITE, objname="ft_site")
    gripper.add_sensor(name="ft_torque", type=mujoco.mjtSensor.mjSENS_TORQUE,
                       objtype=mujoco.mjtObj.mjOBJ_SITE, objname="ft_site")
    gripper.add_sensor(name="ft_acc", type=mujoco.mjtSensor.mjSENS_ACCELEROMETER,
                       objtype=mujoco.mjtObj.mjOBJ_SITE, objname="ft_site")
    site = arm.site("attachment_site")
    arm.attach(gripper, prefix=GRIPPER_PREFIX, site=site)

    mount_site = world.site("robot_mount")
    mount_site.quat = [math.cos(config.base_yaw / 2), 0.0, 0.0, math.sin(config.base_yaw / 2)]
    world.attach(arm, prefix=ARM_PREFIX, site=mount_site)

    # The robot collides only with the receiver (self-collision is not needed: the controller
    # keeps the elbow up and the grasp is a weld, see below).
    for body in world.bodies:
        if body.name.startswith(ARM_PREFIX):
            for geom in body.geoms:
                if geom.contype or geom.conaffinity:
                    geom.contype, geom.conaffinity = ROBOT_CONTYPE, ROBOT_CONAFFINITY
    world.body("object").first_geom().mass = config.object_mass
    add_receiver(world)
    # The grasping hand wraps around the object: no contact between them, nor with the
    # forearm, whose capsule end overlaps a held bottle (a hand is not a capsule).
    world.add_exclude(bodyname1=RECEIVER_PREFIX + "hand_r", bodyname2="object")
    world.add_exclude(bodyname1=RECEIVER_PREFIX + "forearm_r", bodyname2="object")

    # Grasps as soft welds, switched at runtime (data.eq_active); relpose is set on activation.
    pad_body = f"{ARM_PREFIX}{GRIPPER_PREFIX}base"
    world.add_equality(name="gripper_grasp", type=mujoco.mjtEq.mjEQ_WELD, name1=pad_body,
                       name2="object", objtype=mujoco.mjtObj.mjOBJ_BODY, active=False,
                       solref=[0.01, 1.0], solimp=[0.95, 0.99, 0.001, 0.5, 2])
    return world


@lru_cache(maxsize=4)
def _compiled_xml(config: SceneConfig) -> str:
    return build_spec(config).to_xml()


def build_model(config: SceneConfig | None = None) -> mujoco.MjModel:
    """Compile the scene. Compiled models are cached per config (``MjModel`` is copied)."""
    config = config or SceneConfig()
    return _cached_model(config).__copy__()


@lru_cache(maxsize=4)
def _cached_model(config: SceneConfig) -> mujoco.MjModel:
    return build_spec(config).compile()


def scene_ids(model: mujoco.MjModel) -> SceneIds:
    """Look up every index the env and controller need."""

    def nid(obj: mujoco.mjtObj, name: str) -> int:
        i = mujoco.mj_name2id(model, obj, name)
        if i < 0:
            raise KeyError(f"model has no {obj.name} named {name!r}")
        return i

    J, A, S, B, G, E = (
        mujoco.mjtObj.mjOBJ_JOINT,
        mujoco.mjtObj.mjOBJ_ACTUATOR,
        mujoco.mjtObj.mjOBJ_SENSOR,
        mujoco.mjtObj.mjOBJ_BODY,
        mujoco.mjtObj.mjOBJ_GEOM,
        mujoco.mjtObj.mjOBJ_EQUALITY,
    )
    joints = [nid(J, ARM_PREFIX + j) for j in ARM_JOINTS]
    acts = [nid(A, ARM_PREFIX + n) for n in
            ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")]
    obj = nid(B, "object")
    obj_joint = model.body_jntadr[obj]
    robot_geoms = np.array([g for g in range(model.ngeom)
                            if (model.geom_contype[g] or model.geom_conaffinity[g])
                            and model.body_rootid[model.geom_bodyid[g]] == model.body_rootid[
                                nid(B, ARM_PREFIX + "base")]], dtype=np.int64)
    body = body_ids(model)
    gripper_root = nid(B, ARM_PREFIX + GRIPPER_PREFIX + "base_mount")
    ids = SceneIds(
        arm_qpos=model.jnt_qposadr[joints].astype(np.int64),
        arm_dof=model.jnt_dofadr[joints].astype(np.int64),
        arm_act=np.array(acts, dtype=np.int64),
        gripper_act=nid(A, ARM_PREFIX + GRIPPER_PREFIX + "fingers_actuator"),
        gripper_driver_qpos=int(
            model.jnt_qposadr[nid(J, ARM_PREFIX + GRIPPER_PREFIX + "right_driver_joint")]
        ),
        tcp_site=nid(mujoco.mjtObj.mjOBJ_SITE, ARM_PREFIX + GRIPPER_PREFIX + "pinch"),
        ft_site=nid(mujoco.mjtObj.mjOBJ_SITE, ARM_PREFIX + GRIPPER_PREFIX + "ft_site"),
        ft_force_adr=int(model.sensor_adr[nid(S, ARM_PREFIX + GRIPPER_PREFIX + "ft_force")]),
        ft_torque_adr=int(model.sensor_adr[nid(S, ARM_PREFIX + GRIPPER_PREFIX + "ft_torque")]),
        ft_acc_adr=int(model.sensor_adr[nid(S, ARM_PREFIX + GRIPPER_PREFIX + "ft_acc")]),
        gripper_root_body=gripper_root,
        object_body=obj,
        object_qpos=int(model.jnt_qposadr[obj_joint]),
        object_dof=int(model.jnt_dofadr[obj_joint]),
        object_geom=nid(G, "object_geom"),
        body=body,
        eq_gripper=nid(E, "gripper_grasp"),
        robot_geoms=robot_geoms,
        receiver_geoms=body.geoms,
        receiver_geom_names=GEOM_NAMES,
    )
    ids.payload_mass = float(model.body_subtreemass[gripper_root])
    return ids


def activate_weld(model: mujoco.MjModel, data: mujoco.MjData, eq_id: int, torquescale: float = 1.0,
                  zero_force: bool = False) -> None:
    """Switch weld ``eq_id`` on, holding body2 at its current pose relative to body1.

    Sets the weld's ``relpose`` (``model.eq_data``) from ``data.xpos``/``xquat`` so that the
    constraint starts with zero violation, then sets ``data.eq_active``. Call after kinematics.

    With ``zero_force`` the translational anchor is instead offset so that the weld starts with
    zero reference acceleration: MuJoCo's soft constraint pulls with ``-b v - k r``, and for a
    weld switched on while body2 moves at ``v`` relative to body1 (a mocap body has zero velocity
    for the solver) the damping term alone would be an impulse. Placing the anchor at
    ``r = -(b / k) v`` (``b / k = 2 timeconst dampratio²`` for positive ``solref`` beyond the
    impedance width) cancels it, so the grasp force then builds up from zero as the bodies move
    apart, like a hand closing on a moving object.
    """
    b1, b2 = model.eq_obj1id[eq_id], model.eq_obj2id[eq_id]
    rot1 = data.xmat[b1].reshape(3, 3)
    inv_q1 = np.empty(4)
    mujoco.mju_negQuat(inv_q1, data.xquat[b1])
    rel_q = np.empty(4)
    mujoco.mju_mulQuat(rel_q, inv_q1, data.xquat[b2])
    eq = model.eq_data[eq_id]
    eq[:3] = 0.0  # anchor at body2's origin
    offset = data.xpos[b2] - data.xpos[b1]
    if zero_force:
        timeconst, dampratio = model.eq_solref[eq_id]
        if timeconst <= 0:
            raise ValueError(
                "zero_force needs a positive (timeconst, dampratio) solref on the weld"
            )
        v1, v2 = np.empty(6), np.empty(6)
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, b1, v1, 0)
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, b2, v2, 0)
        offset = offset + 2.0 * timeconst * dampratio**2 * (v2[3:] - v1[3:])
    eq[3:6] = rot1.T @ offset
    eq[6:10] = rel_q
    eq[10] = torquescale
    data.eq_active[eq_id] = 1


def place_object_in_gripper(model: mujoco.MjModel, data: mujoco.MjData, ids: SceneIds) -> None:
    """Put the object upright between the finger pads (at the TCP) and weld it to the gripper."""
    mujoco.mj_kinematics(model, data)
    adr = ids.object_qpos
    data.qpos[adr:adr + 3] = data.site_xpos[ids.tcp_site]
    data.qpos[adr + 3:adr + 7] = (1.0, 0.0, 0.0, 0.0)
    data.qvel[ids.object_dof:ids.object_dof + 6] = 0.0
    mujoco.mj_kinematics(model, data)
    activate_weld(model, data, ids.eq_gripper)
