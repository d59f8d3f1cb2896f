"""Where the body contacts over 50 N come from: each one traced to the robot part and the moment.

Runs one agent on the held-out replays of a public-dataset folder (Table I's folds 5-9,
``--per-fold`` of each, spread evenly, as ``evaluate.py closed-loop`` picks them; paper profile,
Θ̂, the replay's hand mode ``reach``) and, for every episode whose body contact force (the
10 ms filtered force the env reports, ``info["body_contact_force"]``) exceeds ``--force``, the
strongest raw contact of each (body segment, robot part) pair over the episode: the force, the
time from the gripper's release, the person's state then and the gripper's finger angle (the
Robotiq 2F-85 driver joint: 0.285 rad closed on the bottle, 0 fully open). Each case is put in
one of four kinds:

* ``before the grasp``: the person walks or reaches and the robot (the held object, the gripper,
  the wrist) meets their body; at the release itself (``t - release`` 0) it is what pulled the
  bottle beyond f_r, a premature release;
* ``both hold``: the person holds the object and the gripper still does;
* ``after the release``: the person holds the object and the gripper has let go: a finger of the
  opening gripper, or the wrist behind it, meets the holding arm or the body while the person
  draws the object out;
* ``other``.

The raw force is the solver's force at the tick (``mj_contactForce``); the reported one is filtered
(``handover_env/envs/contacts.py``). The env's contact monitor is wrapped on this env instance
only (its own bookkeeping is unchanged).

Usage: ``python bench/contact_trace.py --data PATH/whole_motions [--agent giver-replay]
[--per-fold 25] [--person reach_offset arm_yield=off] [--force 50]``
"""

from __future__ import annotations

import argparse
import warnings
from collections import Counter

FINGER_PARTS = ("pad", "coupler", "follower", "driver", "spring_link")


def _kind(state: str, after_release: bool) -> str:
    if state in ("walking", "reaching"):
        return "before the grasp"
    if state == "holding":
        return "after the release" if after_release else "both hold"
    return "other"


def _part(name: str) -> str:
    """The robot part of a geom/body name: object, finger, wrist or arm link."""
    if name.startswith("object"):
        return "object"
    tail = name.rsplit("/", 1)[-1]
    if any(p in tail for p in FINGER_PARTS):
        return "finger"
    return tail


def trace(data: str, agent: str, per_fold: int, person: tuple[str, ...],
          force: float) -> tuple[int, list[dict[str, object]]]:
    """``(episodes, cases)``: every episode over ``force`` N with its strongest contacts."""
    import gymnasium as gym
    import mujoco
    import numpy as np

    import handover_env  # noqa: F401 - registers the envs
    from handover_env.config import HandoverParams
    from handover_env.data.public import load_public_dataset
    from handover_env.envs.contacts import OBJECT, PERSON, ROBOT
    from handover_env.person.settings import switch_tokens
    from handover_eval import receivers as rc
    from handover_eval import roster
    from handover_eval.methods import MethodOptions

    entry = roster.entry(agent)
    if entry.learns or entry.build is None:
        raise ValueError(f"--agent {agent}: a learning or RL agent needs its fold models; "
                         "trace the closed-loop run's agents that do not learn")
    theta = HandoverParams()  # the paper's Θ̂
    dataset = load_public_dataset(data)
    specs = rc.replays(dataset, rc.fold_of(dataset, 10, 0), rc.held_out_folds(10),
                       rc.recording_paths(data, dataset), per_fold)
    env = gym.make("handover_env/DynamicHandover-v0", sensing="paper", params=theta,
                   person=switch_tokens(person) or None).unwrapped
    model, monitor = env.model, env.contacts
    scan = monitor.scan
    f6 = np.zeros(6)
    seen: dict[tuple[str, str], tuple[float, float, str, float]] = {}

    def name(g: int) -> str:
        return (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
                or mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[g]))

    def traced(d: mujoco.MjData) -> None:
        cls = monitor.geom_class
        for i in range(d.ncon):
            c = d.contact[i]
            pair = cls(c.geom1) | cls(c.geom2)
            if pair not in (ROBOT | PERSON, OBJECT | PERSON):
                continue
            mujoco.mj_contactForce(model, d, i, f6)
            g_body, g_robot = ((c.geom1, c.geom2) if cls(c.geom1) == PERSON
                               else (c.geom2, c.geom1))
            key = (name(g_body).rsplit("/", 1)[-1], _part(name(g_robot)))
            f = abs(float(f6[0]))
            if key not in seen or f > seen[key][0]:
                seen[key] = (f, float(d.time), env.receiver.state,
                             float(env._qpos_v[env._gripper_qpos]))  # noqa: SLF001
        scan(d)

    monitor.scan = traced  # type: ignore[method-assign]
    cases = []
    for spec in specs:
        seen.clear()
        policy = entry.build(MethodOptions(), theta)
        episode = rc.replay_source(spec, dataset)
        if hasattr(policy, "set_episode"):
            policy.set_episode(dataset[spec.index])
        policy.reset()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            obs, info = env.reset(seed=spec.seed, options={
                "receiver": "replay", "hand_mode": "reach", "episode": episode})
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy.act(obs))
            done = terminated or truncated
        if info["body_contact_force"] <= force:
            continue
        t_rel = env.t_release
        top = max(seen.items(), key=lambda kv: kv[1][0])
        (segment, part), (f, t, state, finger) = top
        after = t > t_rel + 1e-9  # t_release is NaN without a release: never after
        cases.append({
            "recording": spec.key, "ood": spec.is_ood, "outcome": info["outcome"],
            "filtered": info["body_contact_force"], "segment": segment, "part": part,
            "raw": f, "t_from_release": t - t_rel, "state": state, "finger": finger,
            "kind": _kind(state, after),
        })
    return len(specs), cases


def main(argv: list[str] | None = None) -> int:
    from handover_eval.cli.args import add_person_argument

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, metavar="PATH",
                   help="a public-dataset folder (whole_motions/): its held-out replays")
    p.add_argument("--agent", default="giver-replay", metavar="NAME",
                   help="the agent (a built-in name; default giver-replay)")
    p.add_argument("--per-fold", type=int, default=25, metavar="N",
                   help="replays per held-out fold, spread evenly (default 25: 125 in all)")
    add_person_argument(p)
    p.add_argument("--force", type=float, default=50.0, metavar="N",
                   help="the filtered body-contact force over which an episode is traced (50)")
    args = p.parse_args(argv)
    n, cases = trace(args.data, args.agent, args.per_fold, tuple(args.person), args.force)
    print(f"{args.agent}, person {args.person or 'default'}: {len(cases)} of {n} episodes over "
          f"{args.force:g} N")
    print("| recording | set | outcome | filtered N | segment | robot part | raw N | "
          "t - release (s) | person | finger (rad) | kind |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for c in cases:
        print(f"| {c['recording']} | {'OOD' if c['ood'] else 'ID'} | {c['outcome']} | "
              f"{c['filtered']:.0f} | {c['segment']} | {c['part']} | {c['raw']:.0f} | "
              f"{c['t_from_release']:+.3f} | {c['state']} | {c['finger']:.3f} | {c['kind']} |")
    kinds = Counter(str(c["kind"]) for c in cases)
    pairs = Counter(f"{c['segment']} / {c['part']}" for c in cases)
    print("by kind: " + ", ".join(f"{k} {v}" for k, v in kinds.most_common()))
    print("by segment / robot part: " + ", ".join(f"{k} {v}" for k, v in pairs.most_common()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
