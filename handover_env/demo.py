"""``make demo``: the reactive agent with Θ-hat on a few seeded ID and OOD walkers.

Prints one line per episode (scenario, outcome, handover time, release force, peak force) and
writes PNG frames of the first episode to ``outputs/demo/`` (if offscreen rendering works).
Usage: ``python -m handover_env.demo [--episodes-id 3] [--episodes-ood 2] [--out outputs/demo]``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402

import handover_env  # noqa: E402,F401
from agents.reactive import ReactiveAgent  # noqa: E402
from handover_env.rollout import run_episode  # noqa: E402


def _fmt(v: float | None, unit: str) -> str:
    return "-" if v is None else f"{v:.2f} {unit}"


def run(n_id: int = 3, n_ood: int = 2, out: Path = Path("outputs/demo"), frames_every: int = 6) -> list[dict]:
    """Run the demo episodes; returns their final ``info`` dicts."""
    env = gym.make("handover_env/DynamicHandover-v0", render_mode="rgb_array", width=480, height=360)
    agent = ReactiveAgent()
    results = []
    scenarios = [("id", s) for s in range(n_id)] + [("ood", 100 + s) for s in range(n_ood)]
    for k, (kind, seed) in enumerate(scenarios):
        frames: list = []
        save = k == 0

        def grab(step: int, _info: dict) -> None:
            nonlocal save
            if save and step % frames_every == 0:
                try:
                    frames.append(env.render())
                except Exception as exc:  # no offscreen GL
                    print(f"(no frames: {exc})")
                    save = False

        start = time.perf_counter()
        info = run_episode(env, agent, seed=seed, options={"receiver": kind}, on_step=grab)
        results.append(info)
        print(f"{kind.upper():3s} seed {seed:3d}: {info['outcome']:12s} handover time {_fmt(info['handover_time'], 's'):>8s}"
              f"  release force {_fmt(info['release_force'], 'N'):>8s}  peak force {info['peak_contact_force']:.1f} N"
              f"  ({time.perf_counter() - start:.1f} s wall)", flush=True)
        if frames:
            import imageio.v2 as imageio

            out.mkdir(parents=True, exist_ok=True)
            for i, frame in enumerate(frames):
                imageio.imwrite(out / f"episode0_{i:03d}.png", frame)
            print(f"wrote {len(frames)} frames to {out}/")
    env.close()
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes-id", type=int, default=3)
    parser.add_argument("--episodes-ood", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    args = parser.parse_args()
    start = time.perf_counter()
    run(args.episodes_id, args.episodes_ood, args.out)
    print(f"demo finished in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
