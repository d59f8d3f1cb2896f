"""The wrist F/T model's spurious force along a typical agent trajectory (docs/sensing.md).

The reactive agent hands the bottle to seeded scripted ID walkers on a sensing profile; at every
30 Hz step until the person's hand holds the bottle, the force the release compares with f_r
(``env.wrist.f_ext``: the modelled UR5e sensor with the configured payload estimate, its noise,
offset, drift, tare and filter) minus the exact external force (``env.wrist.f_true``). Before the
grasp nobody touches the bottle, so the difference is what the sensor model adds: the RMS per
axis and of the magnitude, and the largest magnitude.

Usage: ``python bench/spurious_force.py [--walkers N] [--sensing paper|randomized]``
"""

from __future__ import annotations

import argparse

import numpy as np


def measure(sensing: str, walkers: int) -> dict[str, float]:
    """RMS per axis, RMS and max of |f_ext - f_true| (N) before the grasp, over ``walkers``."""
    import gymnasium as gym

    import handover_env  # noqa: F401 - registers the envs
    from agents.reactive import ReactiveAgent

    env = gym.make("handover_env/DynamicHandover-v0", sensing=sensing)
    u = env.unwrapped
    agent = ReactiveAgent()
    diffs = []
    for seed in range(walkers):
        obs, _ = env.reset(seed=seed, options={"receiver": "id"})
        agent.reset()
        done = False
        while not done:
            obs, _, term, trunc, _ = env.step(agent.act(obs))
            done = term or trunc
            if u.receiver_holds or u.released:
                break
            diffs.append(np.asarray(u.wrist.f_ext, float) - np.asarray(u.wrist.f_true, float))
    env.close()
    d = np.array(diffs)
    mag = np.linalg.norm(d, axis=1)
    rms = np.sqrt((d**2).mean(axis=0))
    return {"steps": len(d), "rms_x": rms[0], "rms_y": rms[1], "rms_z": rms[2],
            "rms": float(np.sqrt((mag**2).mean())), "max": float(mag.max())}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--walkers", type=int, default=5, help="ID walkers, seeds 0..N-1 (default 5)")
    p.add_argument("--sensing", choices=("paper", "randomized"), default="paper",
                   help="the sensor profile (default: paper)")
    args = p.parse_args()
    r = measure(args.sensing, args.walkers)
    print(f"spurious wrist force before the grasp, {args.sensing} profile, reactive agent, "
          f"{args.walkers} ID walkers, {r['steps']} steps: RMS {r['rms']:.2f} N (per axis "
          f"{r['rms_x']:.2f} / {r['rms_y']:.2f} / {r['rms_z']:.2f} N), max {r['max']:.2f} N")


if __name__ == "__main__":
    main()
