"""``handover_env/DynamicHandover-v0``: hand an object to a person who keeps walking."""

from __future__ import annotations

from handover_env.envs.base_handover import HandoverEnvBase


class DynamicHandoverEnv(HandoverEnvBase):
    """A UR5e with a Robotiq 2F-85 hands a 0.4 kg bottle to a receiver walking past (Kim et al. 2025).

    The robot (MuJoCo Menagerie models) stands on a pedestal at (0, -0.2, 0.79) in the frame of the
    public Dynamic Handover Dataset, holding the bottle. A receiver walks toward -x past the
    robot's side. When the bottle comes within arm's reach the receiver's right hand reaches for
    it, grasps it and, walking on, pulls. The wrist force/torque sensor measures the pull; when it
    exceeds f_r the gripper opens. The agent picks a Cartesian target at 30 Hz; a Cartesian
    impedance controller (paper Eq. 1, K and B from Θ) tracks it at 200 Hz.

    ## Action Space
    ``Box(4,)`` float32, the Cartesian target for the gripper's pinch point:

    | Num | Action | Min | Max | Unit |
    |-----|--------|-----|-----|------|
    | 0 | x | -0.3 | 0.9 | m |
    | 1 | y | -1.1 | 0.1 | m |
    | 2 | z | 0.8 | 1.6 | m |
    | 3 | yaw of the (horizontal) gripper's approach axis | -pi | pi | rad |

    ## Observation Space
    ``Box(N,)`` float32 with N = 2 W + 30 (W = ``history``, 30 by default; 90 values). Named parts
    (see :class:`handover_env.envs.observation.ObsLayout`):

    | Part | Size | Meaning |
    |------|------|---------|
    | receiver_xy_history | 2 W | receiver pelvis xy seen by a 30 Hz camera, oldest first (noise, latency) |
    | receiver_frames_seen | 1 | frames seen so far |
    | ee_pos, ee_quat | 3 + 4 | gripper TCP pose |
    | ee_linvel, ee_angvel | 3 + 3 | TCP velocity |
    | object_pos | 3 | bottle position |
    | object_held | 1 | 1 while the gripper holds the bottle |
    | wrist_force, wrist_torque | 3 + 3 | external wrench at the wrist F/T sensor (static load removed) |
    | gripper_open | 1 | 1 once released |
    | time | 1 | s since reset |
    | receiver_hand_xyz | 3 | camera estimate of the receiver's right hand |
    | robot_enabled | 1 | 1 when the robot may move (always here) |

    ## Rewards
    Per step: ``-dt`` (time), ``-dt * max(0, |F_ext| - 2 f_r) / 10 N`` (excess wrist force);
    ``+10`` on success, ``-10`` on a failure (dropped, unsafe force, missed).

    ## Starting State
    The arm at its ready pose (TCP at (0.3, -0.4, 1.15), gripper pointing -y) holding the bottle,
    settled. The receiver at the start of its walk: a scripted ID walker (``options["receiver"] =
    "id"``, default), an OOD walker (``"ood"``: wanders or pauses) or a recorded track
    (``"replay"`` with ``options["episode"]``); ``options["height"]`` and ``["speed"]`` fix the
    body height and walking speed. Unknown option keys are ignored.

    ## Episode End
    ``terminated`` on success (released at a pull above f_r, fingers open, the receiver holding the
    bottle clear of the gripper), object dropped, unsafe contact force (> ``safety_force``) or a
    missed handover (the receiver walked past); ``truncated`` only by the TimeLimit (450 steps,
    15 s).

    | info key | Meaning |
    |----------|---------|
    | is_success, outcome | True on success; "running", "success", "dropped", "unsafe_force", "missed" |
    | handover_time | s from when the receiver leaves the start point to the release (paper Sec. V-C) |
    | release_force | N, filtered external wrist force at the release |
    | peak_contact_force | N, max external wrist force or robot-receiver contact force so far |
    | receiver_id, receiver_state, receiver_grasp_time | which receiver; its reach/hold state |

    Values not yet defined (no release, no grasp) are ``None``.

    ## Arguments
    | Argument | Default | Meaning |
    |----------|---------|---------|
    | stiffness, damping, forecast_time, release_force | 114.3, 17.1, 0.14, 7.1 | Θ (paper's Θ-hat) |
    | safety_force | 140.0 | N, ISO/TS 15066 quasi-static hand limit |
    | history | 30 | camera frames of receiver history |
    | obs_noise | 0.0 | m, std of Gaussian noise on camera positions |
    | obs_latency | 0 | camera latency in frames |
    | default_receiver | "id" | receiver when reset() gets no option |
    | object_mass | 0.4 | kg |
    | render_mode, width, height, camera | None, 640, 480, "overview" | rendering |
    """

    static = False
