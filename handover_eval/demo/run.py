"""``make demo``: the paper's planner hands a bottle to simulated people, and the static baseline.

On the embedded default (the synthetic demonstrations), the SPGP planner ("ours", Θ-hat) is fitted
and run in ``DynamicHandover-v0`` on a few seeded ID and OOD walkers; the static baseline runs in
``StaticHandover-v0`` on the same ID walkers. One line per episode: outcome, the paper's handover
time, release force, and the person's effort (how far they reached, how long their arm was out,
peak body contact). The first dynamic episode is written as an mp4 and a still strip (PNG) to
``outputs/demo/`` when offscreen rendering works (``MUJOCO_GL=egl`` or ``osmesa``).

Usage: ``python -m handover_eval.demo [--episodes-id 3] [--episodes-ood 2] [--out outputs/demo]``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import handover_env  # noqa: E402,F401
from agents.nonparametric import NonparametricAgent  # noqa: E402
from agents.static import StaticAgent  # noqa: E402
from handover_env.person.demos import load_any  # noqa: E402
from handover_env.rollout import run_episode  # noqa: E402

VIDEO_FPS = 30


def _fmt(v: float | None, unit: str) -> str:
    return "-" if v is None else f"{v:.2f} {unit}"


def _line(label: str, info: dict, wall: float) -> str:
    return (
        f"{label:16s} {info['outcome']:17s} handover time {_fmt(info['handover_time'], 's'):>7s}"
        f"  release {_fmt(info['release_force'], 'N'):>7s}  reach {info['reach_distance']:.2f} m"
        f"  arm out {info['arm_extended_time']:.2f} s  body contact "
        f"{info['body_contact_force']:5.1f} N"
        f"  ({wall:.1f} s wall)"
    )


def _write_video(frames: list[np.ndarray], out: Path) -> list[Path]:
    import imageio.v2 as imageio

    out.mkdir(parents=True, exist_ok=True)
    video = out / "handover.mp4"
    with imageio.get_writer(
        video, fps=VIDEO_FPS, codec="libx264", quality=7, macro_block_size=8
    ) as w:
        for frame in frames:
            w.append_data(frame)
    picks = [frames[int(k)] for k in np.linspace(len(frames) * 0.35, len(frames) - 1, 3)]
    still = out / "handover.png"
    imageio.imwrite(still, np.concatenate(picks, axis=1))
    return [video, still]


def run(
    n_id: int = 3, n_ood: int = 2, out: Path = Path("outputs/demo"), render: bool = True
) -> list[dict]:
    """Fit the planner on the synthetic default and run the episodes; returns their final infos."""
    start = time.perf_counter()
    agent = NonparametricAgent().fit(load_any(None))
    print(
        f"fitted the SPGP planner on the synthetic default in {time.perf_counter() - start:.1f} s"
    )
    env = gym.make("handover_env/DynamicHandover-v0", render_mode="rgb_array" if render else None,
                   width=640, height=360, camera="walkby")
    results: list[dict] = []
    frames: list[np.ndarray] = []
    for k, (kind, seed) in enumerate(
        [("id", s) for s in range(n_id)] + [("ood", 100 + s) for s in range(n_ood)]
    ):
        record = render and k == 0

        def grab(_step: int, _info: dict) -> None:
            nonlocal record
            if record:
                try:
                    frames.append(env.render())
                except Exception as exc:  # no offscreen GL on this machine
                    print(f"(no video: {type(exc).__name__}: {exc}; set MUJOCO_GL=egl or osmesa)")
                    record = False
                    frames.clear()

        t = time.perf_counter()
        info = run_episode(env, agent, seed=seed, options={"receiver": kind}, on_step=grab)
        results.append(info)
        print(_line(f"ours {kind.upper()} {seed}", info, time.perf_counter() - t), flush=True)
    env.close()
    static = gym.make("handover_env/StaticHandover-v0")
    for seed in range(min(n_id, 2)):
        t = time.perf_counter()
        info = run_episode(static, StaticAgent(), seed=seed, options={"receiver": "id"})
        results.append(info)
        print(_line(f"static ID {seed}", info, time.perf_counter() - t), flush=True)
    static.close()
    if frames:
        for path in _write_video(frames, out):
            print(f"wrote {path}")
    return results


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--episodes-id", type=int, default=3, help="seeded ID walkers for the planner (default 3)"
    )
    parser.add_argument(
        "--episodes-ood", type=int, default=2, help="seeded OOD walkers for the planner (default 2)"
    )
    parser.add_argument(
        "--out", type=Path, default=Path("outputs/demo"), help="where the mp4 and PNG go"
    )
    parser.add_argument("--no-video", action="store_true", help="do not render (no mp4 / PNG)")
    args = parser.parse_args()
    if args.episodes_id < 1 or args.episodes_ood < 0:
        parser.error("--episodes-id must be >= 1 and --episodes-ood >= 0")
    start = time.perf_counter()
    run(args.episodes_id, args.episodes_ood, args.out, render=not args.no_video)
    print(f"demo finished in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
