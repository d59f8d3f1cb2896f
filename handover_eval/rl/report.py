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
    """Success rate and return against env steps for every seed of one run's ``states``
    (:func:`curves_figure`)."""
    form = f"residual on {config.base}" if config.form == "residual" else "from scratch"
    return curves_figure([s["curve"] for s in states],
                         f"{config.algo.upper()} {form}: {config.curve_episodes} fixed training "
                         "receivers")


def curves_figure(curves: list[list[dict]], title: str,
                  labels: list[str] | None = None) -> Any:
    """Success rate and return against env steps for every seed's curve (thin lines, named by
    ``labels`` in the legend) and their IQM with its 95 % stratified bootstrap band
    (:func:`handover_eval.rl.statistics.curve_band`) over the points the seeds share."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from handover_eval.rl.statistics import curve_band

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), constrained_layout=True)
    for ax, (key, label) in zip(axes, (("success_rate", "success rate"),
                                       ("return", "return (HandoverReward)")), strict=True):
        values = [[r[key] for r in c] for c in curves]
        steps = [r["steps"] for r in min(curves, key=len)]
        for v, c, name in zip(values, curves, labels or [None] * len(curves), strict=True):
            ax.plot([r["steps"] for r in c], v, lw=0.8, alpha=0.6, label=name)
        mid, low, high = curve_band(values)
        ax.plot(steps, mid, color="k", lw=2, label=f"IQM of {len(curves)} seeds")
        ax.fill_between(steps, low, high, color="k", alpha=0.15, label="95 % CI (bootstrap)")
        ax.set_xlabel("env steps")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(title)
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


# ---------------------------------------------------------------------- the ablation table
def _pct(v: float) -> str:
    return "–" if not math.isfinite(v) else f"{100 * v:.0f} %"


def _s(v: float) -> str:
    return "–" if not math.isfinite(v) else f"{v:.2f} s"


def _diff(d: tuple[float, float, float, bool], scale: float, digits: int) -> str:
    v, lo, hi, star = d
    return (f"{scale * v:+.{digits}f} [{scale * lo:+.{digits}f}, {scale * hi:+.{digits}f}]"
            f"{'*' if star else ''}")


def ablation_markdown(rows: list, references: list, summary: list[dict]) -> str:
    """The ablation's Markdown (:mod:`handover_eval.rl.ablation`): one line per seed and per
    reference agent, then the per-configuration summary over seeds."""
    from handover_eval.reporting import markdown_table
    from handover_eval.rl.ablation import CONTACT_N

    def scores(s) -> list[str]:
        w_id, w_ood, rep = (s.sets[k] for k in ("walker-id", "walker-ood", "replay-all"))
        prem = sum(int(v["premature"]) for v in s.sets.values())
        early = sum(int(v["premature_before_reach"]) for v in s.sets.values())
        over = [f"{_pct(v['contact_over'])}" for v in (w_id, w_ood, rep)]
        return [f"{_pct(w_id['success'])} · {_s(w_id['handover_time'])}",
                f"{_pct(w_ood['success'])} · {_s(w_ood['handover_time'])}",
                f"{_pct(rep['success'])} · {_s(rep['handover_time'])}",
                " / ".join(over), f"{rep['robot_jerk']:.0f}", f"{prem} ({early})"]

    head = ["configuration", "seed", "curve success (start → end)", "curve handover time",
            "walkers ID", "walkers OOD", "replays", f"contact > {CONTACT_N:.0f} N (ID / OOD / "
            "replays)", "robot jerk, replays (m/s³)", "premature releases (before the reach)",
            "Δ success vs ref, replays (pp)", "Δ time vs ref, replays (s)",
            "Δ time vs ref, walkers ID / OOD (s)",
            "wall (min)", "steps/s"]
    body = []
    for ref in references:
        body.append([f"{ref.agent} (reference)", "–", "–", "–", *scores(ref), "–", "–", "–", "–",
                     "–"])
    for r in rows:
        p = r.paired
        body.append([
            r.label, str(r.seed),
            f"{_pct(r.curve_start['success'])} → {_pct(r.curve_end['success'])}",
            f"{_s(r.curve_start['handover_time'])} → {_s(r.curve_end['handover_time'])}",
            *scores(r.scores), _diff(p["replay-all"]["success"], 100, 0),
            _diff(p["replay-all"]["handover_time"], 1, 2),
            f"{_diff(p['walker-id']['handover_time'], 1, 2)} / "
            f"{_diff(p['walker-ood']['handover_time'], 1, 2)}",
            f"{r.wall_s / 60:.0f}", f"{r.steps_per_s:.0f}"])
    lines = ["# RL ablation", "",
             "Each configuration's seeds (`train.py rl`, 1 env each) and their closed loop "
             "(`evaluate.py closed-loop --rl-checkpoint`, paper profile: 50 ID + 50 OOD scripted "
             "walkers of the evaluation seeds and the 435 held-out replays). Curve: the fixed "
             "training receivers. Success · median handover time over the successes. Δ: the RL "
             "agent minus the run's reference agent, paired on the same receivers, [95 % "
             "bootstrap CI], * the CI excludes 0.", "",
             markdown_table(head, body).rstrip("\n"), "",
             "Over seeds (replays): mean, and IQM [95 % stratified bootstrap CI over seeds].", ""]
    sum_rows = []
    for s in summary:
        su, t = s["success_iqm"], s["handover_time_iqm"]
        sum_rows.append([s["label"], ", ".join(str(x) for x in s["seeds"]), s["reference"],
                         f"{100 * s['success_mean']:+.1f}",
                         f"{100 * su[0]:+.1f} [{100 * su[1]:+.1f}, {100 * su[2]:+.1f}]",
                         f"{s['handover_time_mean']:+.3f}",
                         f"{t[0]:+.3f} [{t[1]:+.3f}, {t[2]:+.3f}]"])
    lines += [markdown_table(["configuration", "seeds", "reference", "Δ success, mean (pp)",
                              "Δ success, IQM (pp)", "Δ time, mean (s)", "Δ time, IQM (s)"],
                             sum_rows).rstrip("\n"), ""]
    flags = {label: next((r.flags for r in rows if r.label == label and r.flags), "")
             for label in dict.fromkeys(r.label for r in rows)}
    lines += ["Flags: " + "; ".join(f"**{label}** `{f}`" if f else
                                    f"**{label}** (not recorded in the earlier table)"
                                    for label, f in flags.items()), ""]
    return "\n".join(lines)


def ablation_figure(rows: list) -> Any:
    """Per seed, the paired handover-time difference against the paired success difference on
    the replays, with their CIs, one colour per configuration."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    labels = list(dict.fromkeys(r.label for r in rows))
    for i, label in enumerate(labels):
        for r in (r for r in rows if r.label == label):
            (s, slo, shi, _), (t, tlo, thi, _) = (r.paired["replay-all"][m]
                                                  for m in ("success", "handover_time"))
            ax.errorbar(100 * s, t, xerr=[[100 * (s - slo)], [100 * (shi - s)]],
                        yerr=[[t - tlo], [thi - t]], fmt="o", color=f"C{i}", capsize=3,
                        label=label if r is next(x for x in rows if x.label == label) else None)
            ax.annotate(f"s{r.seed}", (100 * s, t), textcoords="offset points", xytext=(4, 4),
                        fontsize=8)
    ax.axhline(0, color="k", lw=0.8)
    ax.axvline(0, color="k", lw=0.8)
    ax.axvline(-1, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("Δ success vs reference, replays (pp)")
    ax.set_ylabel("Δ handover time vs reference, replays (s)")
    ax.set_title("RL agents paired against their reference (435 held-out replays)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig
