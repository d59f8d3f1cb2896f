"""The receiver's body in MuJoCo: an articulated, compliant person built with ``MjSpec``.

Structure. The 13 rigid segments of :data:`handover_env.person.skeleton.SEGMENTS` (pelvis, torso,
head, both upper arms, forearms and hands, both thighs and shanks with the feet) form a tree:
the pelvis has a free joint, every other segment a ball joint at its BODY_34 origin joint. Each
segment carries capsule (and one sphere) geoms that collide with the robot and the object, never
with each other or the floor. Gravity is compensated (``gravcomp``): standing up is the
person's own business, not the robot's.

Driving. Each segment has a mocap *target* body, moved by :mod:`handover_env.person.receiver`
along the recorded or scripted motion, and a soft **weld** from target to segment. So the person
follows their motion in free space (the targets lead by the welds' velocity and acceleration lag,
:func:`weld_lag_times`), while a collision with the robot deflects the touched parts with a
bounded, measured force: there is no infinite-mass body pushing through the robot.

Stiffness of the posture. The trunk, head and legs are held with the **effective spring constant
of their body region from ISO/TS 15066:2016, Annex A (Table A.3)**: chest 25 N/mm, pelvis 25,
skull 150, thigh 50, lower leg 60. The arms are held far more softly, with a hand endpoint
stiffness of 1 N/mm (:data:`ARM_POSTURE_STIFFNESS`; measured human arm endpoint stiffness in
relaxed posture is a few hundred N/m to a few N/mm), so an arm struck by the robot gives way at
the shoulder and elbow as a person's does. MuJoCo welds take a stiffness in acceleration units;
:data:`WELD_GAIN` converts, calibrated once so that a static 40 N force at a segment's centre of
mass deflects it by force / K (measured in ``tests/person/test_body_model.py``). Damping gives a
damping ratio of about 1.

Stiffness of the tissue. The ISO constants also set the **contacts**: a robot or object geom
pressing on a region compresses it like that region's tissue (:func:`contact_timeconst`,
:data:`CONTACT_MASS`), a few millimetres at the region's force limit, instead of MuJoCo's
near-rigid default. The quasi-static force limits of the same standard (Table A.2; e.g. hand
140 N, chest 140 N) are reported beside the measured contact forces
(:mod:`handover_env.envs.contacts`).

Masses: de Leva (1996) segment fractions of a body of mass 23 kg/m² x height² (BMI 23).

Geometry is built for the template body (1.725 m) and resized in place for each episode's body
(:func:`apply_dims`): segment offsets, capsule end points and radii, and the bounding volumes
MuJoCo's collision detection uses.

This module is over 500 lines because building the body (:func:`add_receiver`), finding it in a
compiled model (:func:`body_ids`), resizing it per person (:func:`apply_dims`) and calibrating
its weld gains (:func:`calibrate_weld_gains`) share one geometry table (``_GEOMS``) and one set
of stiffness constants; they change together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from handover_env.person.skeleton import N_SEGMENTS, SEG, SEGMENTS, TEMPLATE_HEIGHT, BodyDims, J

PREFIX = "receiver/"
#: ISO/TS 15066:2016 Annex A: effective spring constant (N/mm, Table A.3) and maximum permissible
#: quasi-static contact force (N, Table A.2) of each body region.
ISO_REGIONS: dict[str, tuple[float, float]] = {
    "skull": (150.0, 130.0),
    "chest": (25.0, 140.0),
    "pelvis": (25.0, 180.0),
    "upper_arm": (30.0, 150.0),
    "lower_arm": (40.0, 160.0),
    "hand": (75.0, 140.0),
    "thigh": (50.0, 220.0),
    "lower_leg": (60.0, 130.0),
}
#: de Leva (1996) segment mass fractions (lower trunk = pelvis; upper + middle trunk = torso;
#: shank includes the foot).
MASS_FRACTION = {
    "pelvis": 0.1117, "torso": 0.3229, "head": 0.0694, "upper_arm_r": 0.0271, "forearm_r": 0.0162,
    "hand_r": 0.0061, "upper_arm_l": 0.0271, "forearm_l": 0.0162, "hand_l": 0.0061,
    "thigh_r": 0.1416, "shank_r": 0.0570, "thigh_l": 0.1416, "shank_l": 0.0570,
}
BMI = 23.0
#: The arm's segments yield like the arm they are: a bumped arm gives way at the shoulder and
#: elbow long before its tissue compresses. Their holding stiffness is the human hand's endpoint
#: stiffness with the arm held out (Mussa-Ivaldi, Hogan & Bizzi 1985: 300-800 N/m relaxed;
#: Burdet et al. 2001: up to about 1-2 N/mm with co-contraction), not the ISO tissue value.
ARM_POSTURE_STIFFNESS = 1000.0
ARM_REGIONS = ("upper_arm", "lower_arm", "hand")
#: Weld impedance (MuJoCo ``solimp`` d, constant): the share of the reference acceleration the
#: solver enforces per step.
WELD_IMPEDANCE = 0.5
WELD_DAMPING_RATIO = 1.0
#: Where the body stands in a freshly compiled model (qpos0), well away from the robot: the env
#: moves it to its start at every reset; scenes used without a person leave it here.
PARK_XY = (5.0, -3.0)
#: Contacts carry the body's tissue compliance: a contact with a segment is a spring of its
#: region's ISO/TS 15066 effective spring constant K for a robot-side effective mass of
#: CONTACT_MASS (the gripper with the arm behind it, or a held bottle, a few kg), i.e. a MuJoCo
#: contact time constant sqrt(CONTACT_MASS / K) (5 ms for the skull, 7 ms for the hand, 13 ms for
#: the chest). Impacts then peak near ISO's two-body estimate v sqrt(K mu) instead of a rigid
#: contact's impulse, and a quasi-static contact at the region's limit compresses the body by
#: limit / K (2-6 mm).
CONTACT_MASS = 4.0
CONTACT_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
#: MuJoCo mixes the two geoms' contact parameters by their solmix weights: the body's dominate
#: (a robot geom's 20 ms default would otherwise soften every contact with the person).
CONTACT_SOLMIX = 100.0
#: The BODY_34 ankles of the recordings sit about 8 cm above the floor for the pelvis height
#: (the tracker's legs are short for its pelvis); the shank and foot geoms reach down that far.
FOOT_DROP = 0.08
#: A geom end point at the hand's grip point (:meth:`BodyDims.grip`) instead of a joint.
GRIP = -1
#: Contact geoms: (segment, name, point a, point b, radius), points as (BODY_34 joint or GRIP,
#: offset in the body frame, m at the template height) in the segment's rest frame; a == b is a
#: sphere. A hand is a fist from the wrist to the grip point.
_GEOMS: tuple[tuple[str, str, tuple[int, tuple], tuple[int, tuple], float], ...] = (
    (
        "pelvis",
        "hips",
        (J["LEFT_HIP"], (-0.01, -0.03, 0.0)),
        (J["RIGHT_HIP"], (-0.01, 0.03, 0.0)),
        0.11,
    ),
    (
        "torso",
        "abdomen",
        (J["NAVAL_SPINE"], (0.0, 0.0, -0.02)),
        (J["CHEST_SPINE"], (0.0, 0.0, 0.0)),
        0.12,
    ),
    (
        "torso",
        "chest",
        (J["LEFT_SHOULDER"], (0.02, -0.10, -0.16)),
        (J["RIGHT_SHOULDER"], (0.02, 0.10, -0.16)),
        0.10,
    ),
    (
        "torso",
        "shoulders",
        (J["LEFT_SHOULDER"], (0.0, 0.0, -0.02)),
        (J["RIGHT_SHOULDER"], (0.0, 0.0, -0.02)),
        0.055,
    ),
    ("head", "neck", (J["NECK"], (0.0, 0.0, 0.0)), (J["HEAD"], (0.0, 0.0, -0.08)), 0.05),
    ("head", "skull", (J["HEAD"], (0.01, 0.0, 0.02)), (J["HEAD"], (0.01, 0.0, 0.02)), 0.10),
    (
        "upper_arm_r",
        "upper_arm_r",
        (J["RIGHT_SHOULDER"], (0, 0, 0)),
        (J["RIGHT_ELBOW"], (0, 0, 0)),
        0.045,
    ),
    ("forearm_r", "forearm_r", (J["RIGHT_ELBOW"], (0, 0, 0)), (J["RIGHT_WRIST"], (0, 0, 0)), 0.037),
    ("hand_r", "hand_r", (J["RIGHT_WRIST"], (0, 0, 0)), (GRIP, (0, 0, 0)), 0.035),
    (
        "upper_arm_l",
        "upper_arm_l",
        (J["LEFT_SHOULDER"], (0, 0, 0)),
        (J["LEFT_ELBOW"], (0, 0, 0)),
        0.045,
    ),
    ("forearm_l", "forearm_l", (J["LEFT_ELBOW"], (0, 0, 0)), (J["LEFT_WRIST"], (0, 0, 0)), 0.037),
    ("hand_l", "hand_l", (J["LEFT_WRIST"], (0, 0, 0)), (GRIP, (0, 0, 0)), 0.035),
    ("thigh_r", "thigh_r", (J["RIGHT_HIP"], (0, 0, 0)), (J["RIGHT_KNEE"], (0, 0, 0)), 0.07),
    (
        "shank_r",
        "shank_r",
        (J["RIGHT_KNEE"], (0, 0, 0)),
        (J["RIGHT_ANKLE"], (0, 0, -FOOT_DROP)),
        0.05,
    ),
    (
        "shank_r",
        "foot_r",
        (J["RIGHT_ANKLE"], (0, 0, -FOOT_DROP)),
        (J["RIGHT_FOOT"], (0, 0, -FOOT_DROP)),
        0.035,
    ),
    ("thigh_l", "thigh_l", (J["LEFT_HIP"], (0, 0, 0)), (J["LEFT_KNEE"], (0, 0, 0)), 0.07),
    (
        "shank_l",
        "shank_l",
        (J["LEFT_KNEE"], (0, 0, 0)),
        (J["LEFT_ANKLE"], (0, 0, -FOOT_DROP)),
        0.05,
    ),
    (
        "shank_l",
        "foot_l",
        (J["LEFT_ANKLE"], (0, 0, -FOOT_DROP)),
        (J["LEFT_FOOT"], (0, 0, -FOOT_DROP)),
        0.035,
    ),
)
GEOM_NAMES = tuple(g[1] for g in _GEOMS)
#: Calibration of the weld stiffness: measured quasi-static stiffness / target is 1 with this
#: gain per segment (see the module docstring; ``tests/person/test_body_model.py`` re-measures
#: it). The upper arms are the exception: pushed at the centre of mass they are held by the
#: shoulder and the forearm chain, about 1.1 kN/m however weak their own weld, so their gain is
#: left out of :func:`calibrate_weld_gains` (measured 1.09 and 1.15 kN/m for the right and left
#: arm).
WELD_GAIN = {
    "pelvis": 0.0952,
    "torso": 0.1288,
    "head": 0.2725,
    "upper_arm_r": 0.0255,
    "forearm_r": 0.1054,
    "hand_r": 0.1492,
    "upper_arm_l": 0.0255,
    "forearm_l": 0.1054,
    "hand_l": 0.1492,
    "thigh_r": 0.2168,
    "shank_r": 0.2744,
    "thigh_l": 0.2168,
    "shank_l": 0.2744,
}
_MATERIALS = {
    "pelvis": "trousers",
    "thigh_r": "trousers",
    "thigh_l": "trousers",
    "shank_r": "trousers",
    "shank_l": "trousers",
    "head": "skin",
    "hand_r": "skin",
    "hand_l": "skin",
}


#: The passive damping of every ball joint with the person switch ``joint_damping`` (N m s/rad,
#: relative to the parent segment): the value the body was built with before the switch existed
#: (the persons of benchmark protocols v1 and v2), which no source gave. Without it (the default)
#: the body's damping is its welds', about the intended motion.
PASSIVE_JOINT_DAMPING = 0.5


def set_joint_damping(model: mujoco.MjModel, ids: BodyIds, on: bool) -> None:
    """Give every ball joint of the body :data:`PASSIVE_JOINT_DAMPING` (``on``) or none."""
    model.dof_damping[ids.dofs.start + 6:ids.dofs.stop] = PASSIVE_JOINT_DAMPING if on else 0.0


def segment_mass(name: str, height: float) -> float:
    """Mass of segment ``name`` for a body of ``height`` m, kg."""
    return MASS_FRACTION[name] * BMI * height * height


def contact_timeconst(segment: int) -> float:
    """MuJoCo contact time constant of a segment's geoms, s (see ``CONTACT_MASS``)."""
    k_iso = ISO_REGIONS[SEGMENTS[segment].region][0] * 1000.0
    return math.sqrt(CONTACT_MASS / k_iso)


def target_stiffness(segment: int) -> float:
    """The quasi-static stiffness a segment is held with, N/m (see the module docstring)."""
    s = SEGMENTS[segment]
    if s.region in ARM_REGIONS:
        return ARM_POSTURE_STIFFNESS
    return ISO_REGIONS[s.region][0] * 1000.0


def weld_solref(segment: int, height: float) -> tuple[float, float]:
    """MuJoCo ``solref`` (-stiffness, -damping) of a segment's weld, in acceleration units.

    One free body of mass m under a weld with impedance d and reference stiffness k settles at a
    deflection r = (1 - d) F / (d k m) (MuJoCo: a1 + d (b v + k r) = (1 - d) a0), i.e. a
    quasi-static stiffness d k m / (1 - d); we solve that for k with the region's ISO value and
    correct by the measured :data:`WELD_GAIN` (the segments are coupled through their joints).
    """
    s = SEGMENTS[segment]
    m = segment_mass(s.name, height)
    d = WELD_IMPEDANCE
    k = WELD_GAIN[s.name] * target_stiffness(segment) * (1.0 - d) / (d * m)
    b = 2.0 * WELD_DAMPING_RATIO * math.sqrt(k / d)
    return -k, -b


def _point(dims: BodyDims, segment: int, ref: tuple[int, tuple]) -> np.ndarray:
    joint, offset = ref
    base = dims.grip(SEGMENTS[segment].name[-1]) if joint == GRIP else dims.local(joint, segment)
    return base + np.asarray(offset, dtype=np.float64) * dims.height / 1.725


def _capsule(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(pos, quat, half length) of a capsule from a to b (z axis along a -> b)."""
    d = b - a
    length = float(np.linalg.norm(d))
    quat = np.array([1.0, 0.0, 0.0, 0.0])
    if length > 1e-9:
        mujoco.mju_quatZ2Vec(quat, d / length)
    return 0.5 * (a + b), quat, 0.5 * length


@dataclass(frozen=True)
class _Geometry:
    """Every geom (segment, centre, orientation, half length, radius) and each segment's mass
    and centre of mass (volume-weighted over its geoms) for one body."""

    geoms: list[tuple[int, np.ndarray, np.ndarray, float, float]]
    mass: np.ndarray
    com: np.ndarray


def _geometry(dims: BodyDims) -> _Geometry:
    seg_index = {s.name: i for i, s in enumerate(SEGMENTS)}
    scale = dims.height / 1.725
    geoms = []
    vol = np.zeros(N_SEGMENTS)
    moment = np.zeros((N_SEGMENTS, 3))
    for seg, _, ra, rb, radius in _GEOMS:
        i = seg_index[seg]
        pos, quat, half = _capsule(_point(dims, i, ra), _point(dims, i, rb))
        r = radius * scale
        v = math.pi * r * r * 2 * half + 4.0 / 3.0 * math.pi * r**3
        geoms.append((i, pos, quat, half, r))
        vol[i] += v
        moment[i] += v * pos
    mass = np.array([segment_mass(s.name, dims.height) for s in SEGMENTS])
    return _Geometry(geoms=geoms, mass=mass, com=moment / vol[:, None])


def add_receiver(world: mujoco.MjSpec, dims: BodyDims | None = None, contype: int = 2,
                 conaffinity: int = 1) -> None:
    """Add the receiver's segments, their mocap targets and welds to ``world`` (rest pose at
    origin).

    Args:
        world: the scene spec.
        dims: rest geometry (default: the template body).
        contype, conaffinity: collision bits of the body's geoms (robot: 1/2, object 8/6).
    """
    dims = dims or BodyDims.from_height(1.725)
    offsets = dims.offsets
    geo = _geometry(dims)
    bodies: list[mujoco.MjsBody] = []
    for i, s in enumerate(SEGMENTS):
        parent = world.worldbody if s.parent < 0 else bodies[s.parent]
        pos = [*PARK_XY, dims.pelvis_z] if s.parent < 0 else offsets[i].tolist()
        body = parent.add_body(name=PREFIX + s.name, pos=pos, gravcomp=1.0)
        if s.parent < 0:
            body.add_freejoint(name=PREFIX + "root")
        else:
            body.add_joint(
                name=PREFIX + s.name + "_ball",
                type=mujoco.mjtJoint.mjJNT_BALL,
                damping=0.0,
                armature=0.01,
            )
        bodies.append(body)
    seg_vol = np.zeros(N_SEGMENTS)
    for i, _, _, half, r in geo.geoms:
        seg_vol[i] += math.pi * r * r * 2 * half + 4.0 / 3.0 * math.pi * r**3
    for (i, pos, quat, half, r), name in zip(geo.geoms, GEOM_NAMES):
        seg = SEGMENTS[i].name
        vol = math.pi * r * r * 2 * half + 4.0 / 3.0 * math.pi * r**3
        kind = mujoco.mjtGeom.mjGEOM_SPHERE if half < 1e-9 else mujoco.mjtGeom.mjGEOM_CAPSULE
        bodies[i].add_geom(
            name=PREFIX + name,
            type=kind,
            pos=pos.tolist(),
            quat=quat.tolist(),
            size=[r, max(half, 1e-6), 0.0],
            contype=contype,
            conaffinity=conaffinity,
            mass=float(geo.mass[i] * vol / seg_vol[i]),
            material=_MATERIALS.get(seg, "shirt"),
            solref=[contact_timeconst(i), 1.0],
            solimp=list(CONTACT_SOLIMP),
            solmix=CONTACT_SOLMIX,
        )
    # The right hand's grip point: where it holds the object.
    hand = SEG["hand_r"]
    bodies[hand].add_site(name=PREFIX + "grip_r", pos=dims.grip("r").tolist(),
                          size=[0.01, 0.01, 0.01], group=4)
    rest = np.zeros((N_SEGMENTS, 3))
    for i, s in enumerate(SEGMENTS):
        rest[i] = (
            np.array([*PARK_XY, dims.pelvis_z]) if s.parent < 0 else rest[s.parent] + offsets[i]
        )
        world.worldbody.add_body(name=PREFIX + "target_" + s.name, mocap=True, pos=rest[i].tolist())
        k, b = weld_solref(i, dims.height)
        com = geo.com[i].tolist()
        # Anchor at the segment's centre of mass, on both sides (target pose = segment pose).
        world.add_equality(name=PREFIX + "hold_" + s.name, type=mujoco.mjtEq.mjEQ_WELD,
                           name1=PREFIX + "target_" + s.name, name2=PREFIX + s.name,
                           objtype=mujoco.mjtObj.mjOBJ_BODY, active=True, solref=[k, b],
                           solimp=[WELD_IMPEDANCE, WELD_IMPEDANCE, 0.001, 0.5, 2.0],
                           data=[*com, *com, 1, 0, 0, 0, 1, 0])


def weld_lag_times(model: mujoco.MjModel, ids: BodyIds) -> tuple[np.ndarray, np.ndarray]:
    """(S,) feed-forward gains of each segment's target: (b / k, 1 / k).

    The weld's reference acceleration is -b v - k r; a segment that moves with its target at
    velocity v and acceleration a therefore trails it by r = (b v + a) / k. The receiver puts each
    target that far ahead, so the segment itself sits on its nominal motion.
    """
    k = -model.eq_solref[ids.welds, 0]
    b = -model.eq_solref[ids.welds, 1]
    return b / k, 1.0 / k


@dataclass
class BodyIds:
    """Indices of the receiver's parts in a compiled model (segments in ``SEGMENTS`` order).

    Attributes:
        bodies: (S,) segment body ids.
        mocap: slice of ``data.mocap_pos`` rows of the targets (they are contiguous, in order).
        welds: (S,) equality ids of the holding welds.
        geoms: (G,) geom ids, in ``GEOM_NAMES`` order.
        geom_segment: (G,) segment index of each geom.
        grip_site: site id of the right hand's grip point.
        root_qpos, root_dof: address of the pelvis free joint in qpos / qvel.
        dofs: slice of all the receiver's dofs in qvel.
        ball_qpos: (S,) qpos address of each segment's ball joint (pelvis: its free joint's
            quaternion).
        inertia0: (S, 3) principal inertias of the compiled (template) body.
    """

    bodies: np.ndarray
    mocap: slice
    welds: np.ndarray
    geoms: np.ndarray
    geom_segment: np.ndarray
    grip_site: int
    root_qpos: int
    root_dof: int
    dofs: slice
    ball_qpos: np.ndarray
    inertia0: np.ndarray


def body_ids(model: mujoco.MjModel) -> BodyIds:
    """Look up the receiver's indices in a compiled scene."""
    def nid(obj: mujoco.mjtObj, name: str) -> int:
        i = mujoco.mj_name2id(model, obj, PREFIX + name)
        if i < 0:
            raise KeyError(f"model has no {obj.name} named {PREFIX + name!r}")
        return i

    B = mujoco.mjtObj.mjOBJ_BODY
    bodies = np.array([nid(B, s.name) for s in SEGMENTS], dtype=np.int64)
    mocap = np.array(
        [model.body_mocapid[nid(B, "target_" + s.name)] for s in SEGMENTS], dtype=np.int64
    )
    if not np.all(np.diff(mocap) == 1):
        raise RuntimeError("receiver mocap targets are not contiguous")
    geoms = np.array([nid(mujoco.mjtObj.mjOBJ_GEOM, n) for n in GEOM_NAMES], dtype=np.int64)
    seg_of_body = {int(b): i for i, b in enumerate(bodies)}
    root_joint = nid(mujoco.mjtObj.mjOBJ_JOINT, "root")
    dof0 = int(model.jnt_dofadr[root_joint])
    ball = [int(model.jnt_qposadr[root_joint]) + 3]
    ball += [int(model.jnt_qposadr[model.body_jntadr[b]]) for b in bodies[1:]]
    return BodyIds(
        bodies=bodies,
        mocap=slice(int(mocap[0]), int(mocap[-1]) + 1),
        welds=np.array(
            [nid(mujoco.mjtObj.mjOBJ_EQUALITY, "hold_" + s.name) for s in SEGMENTS], dtype=np.int64
        ),
        geoms=geoms,
        geom_segment=np.array(
            [seg_of_body[int(model.geom_bodyid[g])] for g in geoms], dtype=np.int64
        ),
        grip_site=nid(mujoco.mjtObj.mjOBJ_SITE, "grip_r"),
        root_qpos=int(model.jnt_qposadr[root_joint]),
        root_dof=dof0,
        dofs=slice(dof0, dof0 + 6 + 3 * (N_SEGMENTS - 1)),
        ball_qpos=np.array(ball, dtype=np.int64),
        inertia0=model.body_inertia[bodies].copy(),
    )


def apply_dims(model: mujoco.MjModel, ids: BodyIds, dims: BodyDims) -> None:
    """Resize the compiled body in place for ``dims``: offsets, geoms, masses, welds, bounds.

    Every quantity that depends on the body's size is rewritten: segment offsets, geom poses and
    sizes, each geom's bounding sphere and box and the bodies' bounding-volume nodes (which
    MuJoCo's broad- and mid-phase collision detection read, so contacts with a resized body are
    found as with a freshly compiled one), masses and centres of mass (inertias scale with
    mass x length^2 from the template), the weld anchors and stiffness. Call
    ``mujoco.mj_setConst`` afterwards so that MuJoCo's derived constants follow.
    """
    geo = _geometry(dims)
    offsets = dims.offsets
    for i, s in enumerate(SEGMENTS):
        if s.parent >= 0:
            model.body_pos[ids.bodies[i]] = offsets[i]
    model.body_pos[ids.bodies[0]] = (*PARK_XY, dims.pelvis_z)
    for g, (_, pos, quat, half, r) in zip(ids.geoms, geo.geoms):
        model.geom_pos[g] = pos
        model.geom_quat[g] = quat
        model.geom_size[g, :2] = (r, max(half, 1e-6))
        extent = r + half if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE else r
        model.geom_rbound[g] = extent
        model.geom_aabb[g] = (0.0, 0.0, 0.0, r, r, extent)
    model.site_pos[ids.grip_site] = dims.grip("r")
    template_mass = np.array([segment_mass(s.name, TEMPLATE_HEIGHT) for s in SEGMENTS])
    scale = (geo.mass / template_mass) * (dims.height / TEMPLATE_HEIGHT) ** 2
    model.body_mass[ids.bodies] = geo.mass
    model.body_ipos[ids.bodies] = geo.com
    model.body_inertia[ids.bodies] = ids.inertia0 * scale[:, None]
    for i in range(N_SEGMENTS):
        w = ids.welds[i]
        model.eq_solref[w] = weld_solref(i, dims.height)
        model.eq_data[w, 0:3] = geo.com[i]
        model.eq_data[w, 3:6] = geo.com[i]
    _refresh_bvh(model, ids)


def _refresh_bvh(model: mujoco.MjModel, ids: BodyIds) -> None:
    """Recompute the static bounding-volume boxes of the receiver's bodies (body frame)."""
    for b in ids.bodies:
        adr, num = int(model.body_bvhadr[b]), int(model.body_bvhnum[b])
        if num <= 0:
            continue
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for g in range(model.body_geomadr[b], model.body_geomadr[b] + model.body_geomnum[b]):
            rot = np.empty(9)
            mujoco.mju_quat2Mat(rot, model.geom_quat[g])
            rot = rot.reshape(3, 3)
            c, h = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            center = model.geom_pos[g] + rot @ c
            half = np.abs(rot) @ h
            lo, hi = np.minimum(lo, center - half), np.maximum(hi, center + half)
        box = np.concatenate([(lo + hi) / 2, (hi - lo) / 2])
        for node in range(adr, adr + num):
            model.bvh_aabb[node] = box  # conservative: every node bounds all of the body's geoms


def measure_stiffness(model: mujoco.MjModel, data: mujoco.MjData, ids: BodyIds, segment: int,
                      force: float = 40.0, axis: int = 1, steps: int = 1500) -> float:
    """Quasi-static stiffness of one segment, N/m: a horizontal force at its centre of mass over
    the deflection it causes once settled, with every target held still (the body at qpos0)."""
    mujoco.mj_resetData(model, data)
    mujoco.mj_forward(model, data)
    data.mocap_pos[ids.mocap] = data.xpos[ids.bodies]
    data.mocap_quat[ids.mocap] = data.xquat[ids.bodies]
    mujoco.mj_step(model, data, 300)
    base = data.xipos[ids.bodies[segment], axis]
    data.xfrc_applied[:] = 0.0
    data.xfrc_applied[ids.bodies[segment], axis] = force
    mujoco.mj_step(model, data, steps)
    data.xfrc_applied[:] = 0.0
    return force / (data.xipos[ids.bodies[segment], axis] - base)


def calibrate_weld_gains(iterations: int = 6) -> dict[str, float]:
    """Find :data:`WELD_GAIN` so that every segment's measured stiffness (mean over the two
    horizontal axes) is its :func:`target_stiffness`; how the committed gains were made. The upper
    arms keep their gain: their stiffness is bounded below by their neighbours (see
    :data:`WELD_GAIN`), so the iteration would only drive their own weld towards zero."""
    gains = dict(WELD_GAIN)
    for _ in range(iterations):
        WELD_GAIN.update(gains)
        spec = mujoco.MjSpec()
        spec.option.timestep = 1.0 / 600.0
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        for name in set(_MATERIALS.values()) | {"shirt"}:
            spec.add_material(name=name)
        add_receiver(spec)
        model = spec.compile()
        data = mujoco.MjData(model)
        ids = body_ids(model)
        for i, s in enumerate(SEGMENTS):
            if s.name.startswith("upper_arm"):
                continue
            k = 0.5 * sum(measure_stiffness(model, data, ids, i, axis=a) for a in (0, 1))
            gains[s.name] *= (target_stiffness(i) / k) ** 0.8
    for left, right in (
        ("upper_arm_l", "upper_arm_r"),
        ("forearm_l", "forearm_r"),
        ("hand_l", "hand_r"),
        ("thigh_l", "thigh_r"),
        ("shank_l", "shank_r"),
    ):
        gains[left] = gains[right] = 0.5 * (gains[left] + gains[right])
    return {k: round(v, 4) for k, v in gains.items()}
