"""The learning curve of an RL run: the figure and the console lines."""

from __future__ import annotations

import math
from typing import Any

from baselines.rl.config import RLConfig


def curve_figure(curve: list[dict], config: RLConfig) -> Any:
    """Success rate, handover time and return against env steps on the fixed training
    evaluation set (one panel each)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [r["steps"] for r in curve]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), constrained_layout=True)
    panels = (("success_rate", "success rate", (0.0, 1.02)), ("handover_time", "handover time (s)",
              None), ("return", "return (HandoverReward)", None))
    for ax, (key, label, ylim) in zip(axes, panels, strict=True):
        ax.plot(steps, [r[key] for r in curve], marker="o", ms=3)
        ax.set_xlabel("env steps")
        ax.set_ylabel(label)
        if ylim:
            ax.set_ylim(*ylim)
        ax.grid(alpha=0.3)
    form = f"residual on {config.base}" if config.form == "residual" else "from scratch"
    fig.suptitle(f"{config.algo.upper()} {form}, seed {config.seed}, {config.n_envs} env(s): "
                 f"{config.curve_episodes} fixed training receivers")
    return fig


def summary(state: dict) -> str:
    """The start and end of the learning curve, one line."""
    def fmt(r: dict) -> str:
        t = r["handover_time"]
        return (f"success {r['success_rate']:.2f}, handover time "
                f"{'n/a' if not math.isfinite(t) else f'{t:.2f} s'}, return {r['return']:.2f}")

    c = state["curve"]
    return (f"{state['steps']} env steps, {sum(state['episodes'])} episodes, "
            f"{state['wall_time_s']:.0f} s ({state['steps'] / max(state['wall_time_s'], 1e-9):.0f}"
            f" steps/s); start: {fmt(c[0])}; end: {fmt(c[-1])}")
