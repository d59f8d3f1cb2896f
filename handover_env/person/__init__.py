"""The simulated person who takes the object: body, motion and behaviour, and the
demonstrations it gives (recorded or synthetic). It imports the data model
(:mod:`handover_env.data`), never the robot or the envs. Its per-step work (the decisions, the
pose, the hand, the tick targets, the effort) is compiled (:func:`handover_env.compiled.kernel`).

* :mod:`.skeleton`: the BODY_34 skeleton, body dimensions and segment poses;
* :mod:`.rotations`: swings, frames, yaws and quaternions of the body's segments;
* :mod:`.body_model`: the articulated, compliant body in MuJoCo;
* :mod:`.motion`: scripted walkers (calibrated distributions, field ranges, body proportions);
* :mod:`.trajectory`: a walker's pelvis track, and the shoulder and hand along it;
* :mod:`.gait`: the walking pose of the whole body, and the arm's inverse kinematics;
* :mod:`.person`: a person's nominal motion, scripted or recorded;
* :mod:`.recording`: a public recording with the receiver's skeleton, the replay source;
* :mod:`.synthetic`: the synthetic demonstrations, the scripted person walking past a giver;
* :mod:`.demos`: demonstrations from a ``.npz``, a public folder or the synthetic default;
* :mod:`.settings`: how the person reaches, grasps, holds and pulls (``ReceiverConfig``);
* :mod:`.receiver`: the person during an episode (walk on, reach, grasp, hold, pull);
* :mod:`.receiver_rules`, :mod:`.path_ahead`: the decisions on the remaining walk (left behind,
  the meeting), and that walk built in place at every env step;
* :mod:`.pose`, :mod:`.posing`: the body at a playback position, the arm posed toward the
  hand's target (the whole pose in one compiled call);
* :mod:`.hand_path`: the modelled hand's goal and its minimum-jerk step, per env step;
* :mod:`.targets`: the MuJoCo targets that move the body, at every controller tick;
* :mod:`.effort`: what the handover costs the person (reach, arm-out time, path deviation);
* :mod:`.grip`, :mod:`.min_jerk`: the hand's grip on the object and its minimum-jerk paths.
"""
