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


def seeds_figure(states: list[dict], config: RLConfig) -> Any:
    """Success rate and return against env steps for every seed (thin lines) and their IQM with
    its 95 % stratified bootstrap band (:func:`handover_eval.rl.statistics.curve_band`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from handover_eval.rl.statistics import curve_band

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), constrained_layout=True)
    for ax, (key, label) in zip(axes, (("success_rate", "success rate"),
                                       ("return", "return (HandoverReward)")), strict=True):
        curves = [[r[key] for r in s["curve"]] for s in states]
        steps = [r["steps"] for r in min((s["curve"] for s in states), key=len)]
        for c, s in zip(curves, states, strict=True):
            ax.plot([r["steps"] for r in s["curve"]], c, lw=0.8, alpha=0.5)
        mid, low, high = curve_band(curves)
        ax.plot(steps, mid, color="k", lw=2, label=f"IQM of {len(states)} seeds")
        ax.fill_between(steps, low, high, color="k", alpha=0.15, label="95 % CI (bootstrap)")
        ax.set_xlabel("env steps")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    form = f"residual on {config.base}" if config.form == "residual" else "from scratch"
    fig.suptitle(f"{config.algo.upper()} {form}: {config.curve_episodes} fixed training "
                 "receivers")
    return fig


def seeds_summary(states: list[dict]) -> dict:
    """IQM and 95 % stratified bootstrap CI over seeds of the learning curve's first and last
    success rate and return (one score per seed: the runs of one task)."""
    from handover_eval.rl.statistics import stratified_bootstrap_ci

    out = {"seeds": len(states)}
    for at, index in (("start", 0), ("end", -1)):
        for key in ("success_rate", "return"):
            scores = [[s["curve"][index][key]] for s in states]
            point, low, high = stratified_bootstrap_ci(scores)
            out[f"{at}_{key}"] = {"iqm": point, "ci95": [low, high]}
    return out
