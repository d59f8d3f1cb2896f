"""The receiver's skeleton: the ZED BODY_34 layout, the body's rigid segments and retargeting.

The simulated person (:mod:`handover_env.person.body_model`) is a tree of 15 rigid segments. This
module holds everything about their motion that is independent of MuJoCo:

* the ZED SDK BODY_34 joint layout of the public recordings (``JOINTS``, ``PARENTS``);
* the segment tree (``SEGMENTS``): each segment starts at a BODY_34 joint (its origin, where the
  ball joint to its parent sits) and is rigid; its rest offset from its parent's origin and its
  rest bone vector are given in the parent's frame;
* :class:`BodyPose`: the pose of every segment (origin and rotation), the one representation by
  which recorded skeletons and the scripted walker drive the body;
* :func:`retarget`: recorded joints (T, 34, 3) -> BodyPose, with segment lengths fixed (the model
  is rigid; the ZED tracker fits fixed proportions too, so bone lengths vary by under 6 %);
* :func:`forward_kinematics`: segment rotations + pelvis position -> segment origins.

The rotations themselves (swings, frames, yaws, quaternions) are
:mod:`handover_env.person.rotations`.

Frames. World: the dataset's (z up, floor z = 0). A segment's frame at rest equals the body frame
(x forward, y left, z up): the rest pose stands upright with arms hanging, and each segment's
rotation is measured from it, so the rest pose is all identities. Rotations of limbs are found as
the *swing* of the rest bone onto the recorded bone, applied on top of the parent's rotation (no
twist about the bone, which a capsule does not show); the pelvis, torso and head take their twist
from a second direction (hip line, shoulder line, ear line).

Rest geometry (``TEMPLATE``): median joint positions in the pelvis frame over the walking part of
the development copy's ID recordings (every 8th recording; statistics, not per-recording values),
for a 1.725 m body (the data's median). Scaled linearly with body height.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from handover_env.person.rotations import swing, triad, yaw_matrix

#: ZED SDK BODY_34 joint names, in order (shared/data/README.md).
JOINTS = (
    "PELVIS", "NAVAL_SPINE", "CHEST_SPINE", "NECK", "LEFT_CLAVICLE", "LEFT_SHOULDER",
    "LEFT_ELBOW", "LEFT_WRIST", "LEFT_HAND", "LEFT_HANDTIP", "LEFT_THUMB", "RIGHT_CLAVICLE",
    "RIGHT_SHOULDER", "RIGHT_ELBOW", "RIGHT_WRIST", "RIGHT_HAND", "RIGHT_HANDTIP", "RIGHT_THUMB",
    "LEFT_HIP", "LEFT_KNEE", "LEFT_ANKLE", "LEFT_FOOT", "RIGHT_HIP", "RIGHT_KNEE", "RIGHT_ANKLE",
    "RIGHT_FOOT", "HEAD", "NOSE", "LEFT_EYE", "LEFT_EAR", "RIGHT_EYE", "RIGHT_EAR", "LEFT_HEEL",
    "RIGHT_HEEL",
)
J = {name: i for i, name in enumerate(JOINTS)}
#: Parent of each BODY_34 joint (-1 for the pelvis).
PARENTS = (-1, 0, 1, 2, 2, 4, 5, 6, 7, 8, 7, 2, 11, 12, 13, 14, 15, 14, 0, 18, 19, 20, 0, 22, 23,
           24, 3, 26, 27, 28, 27, 30, 20, 24)
N_JOINTS = len(JOINTS)

#: Median joint positions (m) in the pelvis frame (x forward, y left, z up) while walking, for a
#: 1.725 m body; the pelvis itself is 0.928 m above the floor (median over recordings).
TEMPLATE_HEIGHT = 1.725
TEMPLATE_PELVIS_Z = 0.928
TEMPLATE = np.array([
    [0.0, 0.0, 0.0], [-0.024, -0.003, 0.161], [-0.048, -0.005, 0.321], [-0.072, -0.007, 0.482],
    [-0.071, 0.038, 0.484], [-0.067, 0.177, 0.487], [-0.073, 0.201, 0.224], [-0.056, 0.221, -0.024],
    [-0.053, 0.225, -0.074], [-0.047, 0.232, -0.173], [-0.052, 0.168, -0.129],
    [-0.073, -0.052, 0.482], [-0.078, -0.192, 0.479], [-0.042, -0.241, 0.226],
    [0.021, -0.276, -0.016], [0.033, -0.283, -0.065], [0.056, -0.297, -0.162],
    [0.047, -0.232, -0.122], [0.0, 0.092, 0.002], [0.024, 0.075, -0.379], [-0.038, 0.063, -0.711],
    [0.048, 0.058, -0.806], [0.0, -0.092, -0.002], [0.039, -0.087, -0.383],
    [-0.044, -0.080, -0.709], [0.036, -0.080, -0.810], [-0.005, -0.009, 0.627],
    [-0.005, -0.010, 0.676], [-0.037, 0.018, 0.710], [-0.128, 0.071, 0.688],
    [-0.038, -0.039, 0.710], [-0.128, -0.090, 0.687], [-0.086, 0.060, -0.791],
    [-0.099, -0.079, -0.785],
])


@dataclass(frozen=True)
class Segment:
    """One rigid segment of the body tree.

    Attributes:
        name: segment name (also the MuJoCo body name, prefixed ``receiver/``).
        parent: index of the parent segment in ``SEGMENTS`` (-1 for the pelvis, the root).
        origin: BODY_34 joint at the segment's origin (its ball joint to the parent).
        tip: BODY_34 joint at the far end of its bone (-1: none).
        region: ISO/TS 15066 body region whose stiffness it carries (see body_model).
    """

    name: str
    parent: int
    origin: int
    tip: int
    region: str


SEGMENTS = (
    Segment("pelvis", -1, J["PELVIS"], -1, "pelvis"),
    Segment("torso", 0, J["NAVAL_SPINE"], J["NECK"], "chest"),
    Segment("head", 1, J["NECK"], J["HEAD"], "skull"),
    Segment("upper_arm_r", 1, J["RIGHT_SHOULDER"], J["RIGHT_ELBOW"], "upper_arm"),
    Segment("forearm_r", 3, J["RIGHT_ELBOW"], J["RIGHT_WRIST"], "lower_arm"),
    Segment("hand_r", 4, J["RIGHT_WRIST"], J["RIGHT_HANDTIP"], "hand"),
    Segment("upper_arm_l", 1, J["LEFT_SHOULDER"], J["LEFT_ELBOW"], "upper_arm"),
    Segment("forearm_l", 6, J["LEFT_ELBOW"], J["LEFT_WRIST"], "lower_arm"),
    Segment("hand_l", 7, J["LEFT_WRIST"], J["LEFT_HANDTIP"], "hand"),
    Segment("thigh_r", 0, J["RIGHT_HIP"], J["RIGHT_KNEE"], "thigh"),
    Segment("shank_r", 9, J["RIGHT_KNEE"], J["RIGHT_ANKLE"], "lower_leg"),
    Segment("thigh_l", 0, J["LEFT_HIP"], J["LEFT_KNEE"], "thigh"),
    Segment("shank_l", 11, J["LEFT_KNEE"], J["LEFT_ANKLE"], "lower_leg"),
)
SEG = {s.name: i for i, s in enumerate(SEGMENTS)}
N_SEGMENTS = len(SEGMENTS)
#: Segments whose rotation is the swing of the rest bone onto the recorded bone.
_SWING = tuple(i for i, s in enumerate(SEGMENTS) if s.name not in ("pelvis", "torso", "head"))
RIGHT_ARM = (SEG["upper_arm_r"], SEG["forearm_r"], SEG["hand_r"])
#: Where a hand holds an object: between the HAND joint (knuckles) and the HANDTIP, this
#: fraction of the way (0.4: about 9 cm from the wrist, the centre of a closed grip).
GRIP_ALONG = 0.4


@dataclass(frozen=True)
class BodyDims:
    """Rest geometry of one body: every segment's origin offset and bone in its parent's frame.

    Attributes:
        height: body height, m.
        pelvis_z: pelvis height above the floor when standing, m.
        joints: (34, 3) rest joint positions in the pelvis frame, m (TEMPLATE scaled, or measured).
    """

    height: float
    pelvis_z: float
    joints: np.ndarray

    @classmethod
    def from_height(cls, height: float) -> BodyDims:
        """The template body scaled to ``height`` (m)."""
        if not (math.isfinite(height) and 1.0 <= height <= 2.3):
            raise ValueError(f"height must be in [1.0, 2.3] m, got {height}")
        s = height / TEMPLATE_HEIGHT
        return cls(float(height), TEMPLATE_PELVIS_Z * s, TEMPLATE * s)

    @property
    def offsets(self) -> np.ndarray:
        """(S, 3) origin of each segment relative to its parent's origin (root: zeros)."""
        out = np.zeros((N_SEGMENTS, 3))
        for i, s in enumerate(SEGMENTS):
            if s.parent >= 0:
                out[i] = self.joints[s.origin] - self.joints[SEGMENTS[s.parent].origin]
        return out

    @property
    def bones(self) -> np.ndarray:
        """(S, 3) rest bone vector of each segment (origin -> tip; pelvis: to the naval spine)."""
        out = np.zeros((N_SEGMENTS, 3))
        for i, s in enumerate(SEGMENTS):
            tip = s.tip if s.tip >= 0 else J["NAVAL_SPINE"]
            out[i] = self.joints[tip] - self.joints[s.origin]
        return out

    def local(self, joint: int, segment: int) -> np.ndarray:
        """Rest position of BODY_34 ``joint`` in the frame of ``segment`` (relative to its
        origin)."""
        return self.joints[joint] - self.joints[SEGMENTS[segment].origin]

    def grip(self, side: str = "r") -> np.ndarray:
        """Rest position of the grip point (:data:`GRIP_ALONG`) in its hand segment's frame."""
        prefix = "RIGHT" if side == "r" else "LEFT"
        hand, tip = self.joints[J[prefix + "_HAND"]], self.joints[J[prefix + "_HANDTIP"]]
        return hand + GRIP_ALONG * (tip - hand) - self.joints[SEGMENTS[SEG["hand_" + side]].origin]


@dataclass
class BodyPose:
    """Pose of every segment at one or more instants.

    Attributes:
        origin: (..., S, 3) world position of each segment's origin, m.
        rot: (..., S, 3, 3) world rotation of each segment (columns: its x, y, z axes).
    """

    origin: np.ndarray
    rot: np.ndarray


# ------------------------------------------------------------------------------ kinematics
def forward_kinematics(pelvis: np.ndarray, rot: np.ndarray, dims: BodyDims) -> np.ndarray:
    """(..., S, 3) segment origins from the pelvis origin (..., 3) and rotations (..., S, 3, 3)."""
    offsets = dims.offsets
    origin = np.empty(rot.shape[:-2] + (3,))
    origin[..., 0, :] = pelvis
    for i, s in enumerate(SEGMENTS[1:], start=1):
        origin[..., i, :] = origin[..., s.parent, :] + rot[..., s.parent, :, :] @ offsets[i]
    return origin


def retarget(joints: np.ndarray, dims: BodyDims) -> BodyPose:
    """Recorded BODY_34 joints (..., 34, 3) -> the rigid body's pose (lengths from ``dims``).

    Pelvis: its recorded position, yaw from the hip line (walking direction), upright. Torso:
    spine (naval -> neck) with the shoulder line. Head: neck -> head with the ear line. Limbs:
    swing of the rest bone onto the recorded bone on top of the parent's rotation. Segment
    origins then follow from :func:`forward_kinematics`, so the target is always a pose the
    rigid model can take.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.shape[-2:] != (N_JOINTS, 3):
        raise ValueError(f"joints must have shape (..., {N_JOINTS}, 3), got {joints.shape}")
    if not np.all(np.isfinite(joints)):
        raise ValueError("joints contain NaN or inf")
    lead = joints.shape[:-2]
    rot = np.empty(lead + (N_SEGMENTS, 3, 3))
    hips = joints[..., J["LEFT_HIP"], :] - joints[..., J["RIGHT_HIP"], :]
    rot[..., 0, :, :] = yaw_matrix(np.arctan2(-hips[..., 0], hips[..., 1]))
    rest = dims.joints
    rest_spine = rest[J["NECK"]] - rest[J["NAVAL_SPINE"]]
    rest_sh = rest[J["LEFT_SHOULDER"]] - rest[J["RIGHT_SHOULDER"]]
    spine = joints[..., J["NECK"], :] - joints[..., J["NAVAL_SPINE"], :]
    sh = joints[..., J["LEFT_SHOULDER"], :] - joints[..., J["RIGHT_SHOULDER"], :]
    rot[..., 1, :, :] = triad(spine, sh) @ triad(rest_spine, rest_sh).T
    rest_neck = rest[J["HEAD"]] - rest[J["NECK"]]
    rest_ears = rest[J["LEFT_EAR"]] - rest[J["RIGHT_EAR"]]
    neck = joints[..., J["HEAD"], :] - joints[..., J["NECK"], :]
    ears = joints[..., J["LEFT_EAR"], :] - joints[..., J["RIGHT_EAR"], :]
    rot[..., 2, :, :] = triad(neck, ears) @ triad(rest_neck, rest_ears).T
    bones = dims.bones
    for i in _SWING:
        s = SEGMENTS[i]
        parent = rot[..., s.parent, :, :]
        rest_dir = parent @ bones[i]
        cur = joints[..., s.tip, :] - joints[..., s.origin, :]
        rot[..., i, :, :] = swing(rest_dir, cur) @ parent
    pelvis = joints[..., J["PELVIS"], :]
    return BodyPose(origin=forward_kinematics(pelvis, rot, dims), rot=rot)


#: The segment that carries each BODY_34 joint (its origin segment's parent for origin joints).
def _joint_owner() -> np.ndarray:
    owner = np.zeros(N_JOINTS, dtype=np.int64)
    for i, s in enumerate(SEGMENTS):
        owner[s.origin] = i if s.parent < 0 else s.parent
        if s.tip >= 0:
            owner[s.tip] = i
    extra = {
        "NOSE": "head",
        "LEFT_EYE": "head",
        "RIGHT_EYE": "head",
        "LEFT_EAR": "head",
        "RIGHT_EAR": "head",
        "CHEST_SPINE": "torso",
        "LEFT_CLAVICLE": "torso",
        "RIGHT_CLAVICLE": "torso",
        "LEFT_SHOULDER": "torso",
        "RIGHT_SHOULDER": "torso",
        "LEFT_HIP": "pelvis",
        "RIGHT_HIP": "pelvis",
        "LEFT_HAND": "hand_l",
        "RIGHT_HAND": "hand_r",
        "LEFT_THUMB": "hand_l",
        "RIGHT_THUMB": "hand_r",
        "LEFT_FOOT": "shank_l",
        "RIGHT_FOOT": "shank_r",
        "LEFT_HEEL": "shank_l",
        "RIGHT_HEEL": "shank_r",
    }
    for name, seg in extra.items():
        owner[J[name]] = SEG[seg]
    return owner


JOINT_OWNER = _joint_owner()


def joints_of(pose: BodyPose, dims: BodyDims) -> np.ndarray:
    """(..., 34, 3) BODY_34 joints of a body pose: every joint rides rigidly on its segment.

    The inverse of :func:`retarget` for poses of the rigid model (e.g. to make a replayable
    skeleton from the scripted walker).
    """
    owner = JOINT_OWNER
    local = np.stack([dims.local(j, int(owner[j])) for j in range(N_JOINTS)])
    return pose.origin[..., owner, :] + np.einsum(
        "...jab,jb->...ja", pose.rot[..., owner, :, :], local
    )


def _bone_pairs() -> tuple[tuple[int, int], ...]:
    """(joint, other joint) pairs whose distance the body model needs to be non-zero."""
    pairs = [(j, PARENTS[j]) for j in range(1, N_JOINTS)]  # measure_dims' bone lengths
    pairs += [(s.tip, s.origin) for s in SEGMENTS if s.tip >= 0]  # retarget's bone directions
    pairs += [(J["LEFT_HIP"], J["RIGHT_HIP"]), (J["LEFT_SHOULDER"], J["RIGHT_SHOULDER"]),
              (J["LEFT_EAR"], J["RIGHT_EAR"])]  # the pelvis', torso's and head's twist
    return tuple(dict.fromkeys(pairs))


BONE_PAIRS = _bone_pairs()


def shortest_bone(joints: np.ndarray) -> tuple[float, int, str]:
    """The shortest bone of recorded joints (T, 34, 3): (length in m, frame, ``"A-B"`` name).

    Bones are :data:`BONE_PAIRS`: every joint to its parent, every segment's bone and the hip,
    shoulder and ear lines; a zero-length one leaves :func:`retarget` without a direction.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (N_JOINTS, 3) or joints.shape[0] < 1:
        raise ValueError(f"joints must have shape (T, {N_JOINTS}, 3), got {joints.shape}")
    a, b = (np.array(side) for side in zip(*BONE_PAIRS, strict=True))
    lengths = np.linalg.norm(joints[:, a] - joints[:, b], axis=-1)  # (T, bones)
    frame, k = np.unravel_index(int(np.argmin(lengths)), lengths.shape)
    return float(lengths[frame, k]), int(frame), f"{JOINTS[a[k]]}-{JOINTS[b[k]]}"


def measure_dims(joints: np.ndarray, height: float | None = None) -> BodyDims:
    """Rest geometry of a recorded person: median joint offsets in the pelvis frame.

    Args:
        joints: (T, 34, 3) recorded (filtered) joints.
        height: body height to report, m; default: estimated as the median head-joint height
            (HEAD, the centre of the head) times the template's ratio.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (N_JOINTS, 3) or joints.shape[0] < 1:
        raise ValueError(f"joints must have shape (T, {N_JOINTS}, 3), got {joints.shape}")
    hips = joints[:, J["LEFT_HIP"]] - joints[:, J["RIGHT_HIP"]]
    frame = yaw_matrix(np.arctan2(-hips[:, 0], hips[:, 1]))
    rel = np.einsum("tji,tkj->tki", frame, joints - joints[:, :1])
    med = np.median(rel, axis=0)
    # Use the template for the arms' and legs' rest *directions* (a walking person's median
    # arm is not hanging straight) but the measured lengths, so rest rotations are the template's.
    out = med.copy()
    tmpl = TEMPLATE
    for j in range(1, N_JOINTS):
        p = PARENTS[j]
        length = float(np.median(np.linalg.norm(joints[:, j] - joints[:, p], axis=-1)))
        d = tmpl[j] - tmpl[p]
        out[j] = out[p] + d / max(np.linalg.norm(d), 1e-9) * length
    pelvis_z = float(np.median(joints[:, 0, 2]))
    if height is None:
        head = float(np.median(joints[:, J["HEAD"], 2]))
        height = head * TEMPLATE_HEIGHT / (TEMPLATE_PELVIS_Z + TEMPLATE[J["HEAD"], 2])
    return BodyDims(float(height), pelvis_z, out)
