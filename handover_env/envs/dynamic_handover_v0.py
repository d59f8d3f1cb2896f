"""``handover_env/DynamicHandover-v0``: hand an object to a person who keeps walking."""

from __future__ import annotations

from handover_env.envs.base_handover import HandoverEnvBase


class DynamicHandoverEnv(HandoverEnvBase):
    """A UR5e with a Robotiq 2F-85 hands a 0.4 kg bottle to a receiver walking past (Kim et al.
    2025).

    The robot (MuJoCo Menagerie models) stands on a pedestal at (0, -0.2, 0.79) in the frame of the
    public Dynamic Handover Dataset, holding the bottle. A simulated person (an articulated,
    compliant body: :mod:`handover_env.person.body_model`) walks toward -x past the robot's side, as a
    scripted walker or a replayed recording. When the bottle will be at a comfortable place along
    their walk soon, their right hand reaches for it (calibrated to the recorded transfers:
    :mod:`handover_env.person.receiver`), grasps it and, walking on, pulls. The wrist force/torque
    sensor measures the pull; when it exceeds f_r the gripper opens. The agent picks a Cartesian
    target at 30 Hz; a Cartesian impedance controller (paper Eq. 1, K and B from Θ) tracks it at
    200 Hz.

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
    |---|---|---|
    | receiver_xy_history | 2 W | receiver pelvis xy seen by the 30 Hz camera model, oldest first |
    | receiver_frames_seen | 1 | frames delivered so far (0 until the first arrives, latency) |
    | ee_pos, ee_quat | 3 + 4 | gripper TCP pose |
    | ee_linvel, ee_angvel | 3 + 3 | TCP velocity |
    | object_pos | 3 | bottle position |
    | object_held | 1 | 1 while the gripper holds the bottle |
    | wrist_force, wrist_torque | 3 + 3 | wrist F/T: the force as the sensor model measures it; torque exact |
    | gripper_open | 1 | 1 once released |
    | time | 1 | s since reset |
    | receiver_hand_xyz | 3 | camera model's estimate of the receiver's right hand |
    | robot_enabled | 1 | 1 when the robot may move (always here) |

    ## Sensing (issue 24; every number's source: docs/sensing.md)
    ``sensing="paper"`` (default) is the robot the paper had; ``"ideal"`` the exact world (no
    latency, noise or payload error; the Λ(q) controller); ``"randomized"`` draws each field per
    episode from its documented range (seeded through ``np_random``). ``sensors={"camera": {...},
    "wrist": {...}, "controller": {...}}`` overrides any field (:mod:`handover_env.sensors`).

    | Part | "paper" | "ideal" | Source |
    |---|---|---|---|
    | camera (ZED 2i, body tracking) | 30 Hz, 100 ms latency, pelvis 5.1 mm / hand 62.5 mm noise (ρ 0.954), 0.125 % lost frames | exact, no delay | paper Sec. V-B; Stereolabs; the recordings |
    | wrist F/T (UR5e) | precision 3.5 N (3σ), accuracy 4.0 N, drift 0.24 N/√s, payload error 0.136 kg / 7.7 mm, zeroed at reset, 15 ms filter | exact estimate, 15 ms filter | UR5e datasheet; UR ROS driver issues |
    | controller | constant M = 4.7 kg (Eq. 1), command delay 5 ms, joints ≤ 180°/s, TCP reference ≤ 1 m/s | M = Λ(q), no delay or limits | paper Sec. III-A; ``constant_inertia``; UR5e datasheet |

    The release compares f_r with the *measured* force; the exact one is
    ``env.unwrapped.wrist.f_true``. ``info["sensing"]`` names the profile; the reset's ``info``
    also has ``sensing_params`` (every field in force).

    ## Rewards
    Per step: ``-dt`` (time), ``-dt * max(0, |F_ext| - 2 f_r) / 10 N`` (excess wrist force);
    ``+10`` on success, ``-10`` on a failure (dropped, unsafe force, missed). The weights are
    :class:`handover_env.envs.tasks.base.HandoverReward`'s (``reward={"success": 5.0}`` or a
    task's ``reward=``); each step's terms are in ``info`` as ``reward_time``, ``reward_force`` and
    ``reward_outcome`` (their sum is the reward).

    ## Task
    :class:`handover_env.envs.tasks.dynamic.DynamicHandover` (receiver set-up, episode end,
    reward); ``task=`` gives the env another :class:`~handover_env.envs.tasks.base.HandoverTask`.

    ## Starting State
    The arm at its ready pose (TCP at (0.3, -0.4, 1.15), gripper pointing -y) holding the bottle,
    settled. The person at the start of their walk: a scripted ID walker (``options["receiver"] =
    "id"``, default), an OOD walker (``"ood"``: wanders or pauses) or a recorded person
    (``"replay"`` with ``options["episode"]``: a ``Recording`` with the BODY_34 skeleton, an
    ``Episode`` or a dict of arrays; ``options["hand_mode"]`` ``"reach"`` (modelled hand) or
    ``"recorded"``); ``options["height"]`` and ``["speed"]`` fix the body height and walking
    speed, ``options["walker"]`` any other field of a scripted walker
    (:class:`handover_env.person.motion.WalkerParams`, e.g. ``{"pass_y": -1.0}``). Unknown
    option keys are warned about by name.

    ## Episode End
    ``terminated`` on success (released at a pull above f_r, fingers open, the person holding the
    bottle clear of the gripper), a premature release (the gripper opened before the hand held the
    bottle), object dropped, unsafe force (the pull above ``safety_force`` or a body contact above
    its region's ISO/TS 15066 limit) or a missed handover (the person walked past); ``truncated``
    only by the TimeLimit (450 steps, 15 s).

    | info key | Meaning |
    |---|---|
    | is_success, outcome | True on success; "running", "success", "premature_release", "dropped", "unsafe_force", "missed" |
    | handover_time | s from when the receiver leaves the start point to the release (paper Sec. V-C) |
    | transfer_time, transfer_pelvis_xy, transfer_object_pos | the person's grasp: when, where they were, where the bottle was |
    | transfer_object_body, transfer_object_speed, transfer_robot_jerk | the presentation at the grasp: the bottle's centre forward, left and up of the pelvis in the walking frame (m; as the recordings' `object_fwd/lat/up_transfer`), its speed (m/s) and the TCP's jerk over the last 30 Hz step (m/s^3) |
    | release_time, release_force, pull_force | the release; N, wrist force then; N, peak grip force while both held |
    | peak_contact_force, peak_wrist_force | N, max measured wrist force or body contact force so far |
    | reach_distance, arm_extended_time | m, right shoulder to the object's centre when the person took it (0 before; as the recordings' `object_shoulder_transfer`); s, the arm out (reaching, raised, holding) |
    | time_lost, min_speed_factor, path_deviation | s behind the nominal walk; slowest speed factor; m pushed off the path |
    | contact_force_<segment>, body_contact_force, penetration | N per body segment, N max; m, deepest |
    | body_contact_robot, body_contact_object | whether the robot / the bottle touched the person |
    | robot_jerk_rms, robot_jerk_peak | m/s^3, TCP jerk |
    | sensing (reset: sensing_params) | the sensor profile's name (reset: all its fields) |
    | receiver_id, receiver_state, reach_onset_time, departure_time | which person; their state |

    Values not yet defined (no release, no grasp) are ``None``.

    ## Arguments
    The fields of :class:`handover_env.envs.config.EnvConfig` (validated there), as keywords or
    as one ``config=EnvConfig(...)``:

    | Argument | Default | Meaning |
    |---|---|---|
    | params | ``HandoverParams()`` | Θ (the paper's Θ-hat 114.3, 17.1, 0.14, 7.1), or a dict of its fields; the env reads K, B (Eq. 1) and f_r (``handover_env.config.ROBOT_FIELDS``), t_f is the agent's |
    | stiffness, damping, forecast_time, release_force | | Θ's fields as loose keywords, for ``gym.make`` users (instead of ``params``, not beside it) |
    | safety_force | 140.0 | N, ISO/TS 15066 quasi-static hand limit |
    | history | 30 | camera frames of receiver history |
    | sensing | "paper" | sensor profile: "paper", "ideal" or "randomized" (see Sensing) |
    | sensors | None | ``{"camera": {...}, "wrist": {...}, "controller": {...}}`` field overrides |
    | obs_noise, obs_latency | None | camera overrides: white noise (m) on both keypoints; latency in frames |
    | force_filter_tau | None | wrist override: the force filter's time constant (s; the profile's 15 ms) |
    | default_receiver | "id" | receiver when reset() gets no option |
    | object_mass | 0.4 | kg |
    | miss_distance | 0.35 | m behind the shoulder at which an unheld bottle is walked past |
    | person | None | dict of :class:`handover_env.person.settings.ReceiverConfig` overrides |
    | task | None | a :class:`~handover_env.envs.tasks.base.HandoverTask` instead of ``DynamicHandover`` |
    | reward | None | :class:`~handover_env.envs.tasks.base.HandoverReward` weights (or a dict of them) |
    | render_mode, width, height, camera | None, 640, 480, "overview" | rendering |

    ## Version History
    * v0: the UR5e with the Robotiq 2F-85 (MuJoCo Menagerie models) holding a 0.4 kg bottle,
      driven by the Cartesian impedance controller (Eq. 1, Θ-hat) at 200 Hz toward the agent's
      30 Hz Cartesian target. The receiver is an articulated, compliant person (rigid segments
      following their motion through soft welds, ISO/TS 15066 stiffness and force limits): a
      scripted ID or OOD walker, or a replayed recording with a modelled or the recorded hand,
      who reaches, grasps and pulls. The gripper opens when the filtered wrist force exceeds
      f_r. Outcomes success, premature_release, dropped, unsafe_force, missed and unstable;
      TimeLimit 450 steps (15 s). Sensing (issue 24): the camera, wrist F/T and controller of
      the paper's robot by default (``sensing="paper"``); ``sensing="ideal"`` is the env before
      it, same-seed rollouts byte for byte. With a joint speed limit (the paper profile) the
      controller speed-scales its reference as the UR controller does, instead of only clamping
      joint accelerations at the limit; "ideal" is unchanged. Contacts of the object with the
      person count as the robot's while the robot holds it or nobody does, no longer once the
      person alone holds it (the physics is unchanged; contact figures after the take change).
      The person's arm yields to the robot and a held object leaves the gripper by its open
      side (the person switches ``arm_yield`` and ``avoid_gripper``, on by default since
      benchmark protocol v2; both off give the person before, same-seed rollouts byte for
      byte). The id stays v0: the benchmark's protocol version marks the change.
    """
