"""Markdown, CSV and PNG of the simulated user study (:func:`.study.run_study`'s result)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from agents.cospar import THETA_NAMES
from handover_env.config import HandoverParams
from handover_eval.preference.study import PAPER, StudyResult
from handover_eval.preference.tuning import PAPER_THETA
from handover_eval.preference.tuning_report import save_run, theta_line
from handover_eval.reporting import write_csv, write_png, write_text

SOURCE = (
    "**Simulated participants** (`agents/participants.py`: a documented model of how people judge "
    "a handover from its measured outcomes), **not people**. The paper's figures come from 8 real "
    "volunteers."
)


def _ms(m: float, s: float, unit: str = "", digits: int = 2) -> str:
    if not math.isfinite(m):
        return "–"
    sd = f"{s:.{digits}f}" if math.isfinite(s) else "–"
    return f"{m:.{digits}f}{unit} ± {sd}{unit}"


def _p(p: float) -> str:
    if not math.isfinite(p):
        return "–"
    return f"{p:.2g}" if p >= 1e-4 else "< 1e-4"


def walker_mix(result: StudyResult) -> str:
    """Which walkers the participants walked as (ID / OOD scripted walkers or replays), how many
    episodes, and how their walks were drawn."""
    n = int(result.timings.get("episodes", 0))
    kind = result.receiver
    counts = {"id": n if kind == "id" else 0, "ood": n if kind == "ood" else 0,
              "replay": n if kind == "replay" else 0}
    drawn = (
        "scripted walkers (`reset(seed)`, `handover_env.person.motion.sample_walker`) with the "
        "participant's own body (height, walking speed, passing line); participant `pid` walks "
        "seeds `1000 * pid + 100 * stream + k` (stream 0: the CoSpar tuning walks, 1: the H1/H2 "
        "trials and H3 A/B tests, 2: the personalised comparison), so no two participants share "
        "a walk, tuning never sees a trial walk, and both conditions of a trial meet the same walk"
        if kind != "replay"
        else "replayed dataset episodes with the participant's body height"
    )
    return (
        f"Walker mix: {counts['id']} ID and {counts['ood']} OOD walks"
        + (f" and {counts['replay']} replays" if counts["replay"] else "")
        + f" over all {n} episodes (every part runs the `{kind}` walkers, sensing profile "
        f"`{result.sensing}`): {drawn}."
    )


def markdown(result: StudyResult) -> str:
    """The report's text."""
    c, cfg = result.h1_h2, result.config
    com, tim, h3 = c["comfort"], c["time"], result.h3
    pd, ps = PAPER["comfort_dynamic"], PAPER["comfort_static"]
    td, ts = PAPER["time_dynamic"], PAPER["time_static"]
    lines = [
        "# User study with simulated participants (paper Sec. V-B)",
        "",
        SOURCE,
        "",
        (
            f"{len(result.participants)} participants (seed {cfg.seed}), {cfg.trials} trials per "
            "condition, "
            f"CoSpar {cfg.iterations} iterations on a {'x'.join(map(str, cfg.grid))} grid, "
            f"{cfg.walks} tuning walks "
            f"per Θ, agent `{cfg.agent}`."
        ),
        "",
        walker_mix(result),
        "",
        "## Population Θ̂ (CoSpar pooled over the participants)",
        "",
        f"- ours: {theta_line(result.theta_pop)}" + (" (given with --theta)" if cfg.theta else ""),
        f"- the paper's: {theta_line(HandoverParams(*PAPER_THETA))}",
        "",
        "## H1 (comfort, Q1 Likert 1-5) and H2 (handover time) — dynamic vs static",
        "",
        (
            "| measure | dynamic (ours) | static (ours) | paired t-test p | Cohen's d_z | d_av | "
            "paper dynamic | "
            "paper static | paper p | paper d |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|",
        (
            f"| comfort (Likert) | {_ms(com['mean_a'], com['sd_a'])} | "
            f"{_ms(com['mean_b'], com['sd_b'])} | "
            f"{_p(com['p'])} | {com['d_z']:.2f} | {com['d_av']:.2f} | {pd[0]} ± {pd[1]} | {ps[0]} "
            f"± {ps[1]} | "
            f"{PAPER['comfort_p']} | {PAPER['comfort_d']} |"
        ),
        (
            f"| handover time (s) | {_ms(tim['mean_b'], tim['sd_b'], ' s')} | "
            f"{_ms(tim['mean_a'], tim['sd_a'], ' s')} | "
            f"{_p(tim['p'])} | {tim['d_z']:.2f} | {tim['d_av']:.2f} | {td[0]} ± {td[1]} s | "
            f"{ts[0]} ± {ts[1]} s | "
            f"{PAPER['time_p']} | {PAPER['time_d']} |"
        ),
        "",
        (
            f"M ± SD over participants of their trial averages (n = {com['n']} / {tim['n']} "
            "pairs). Handover time: "
            "from setting off to the gripper's release, the static robot's 2 s stabilisation "
            "delay excluded (as in "
            "the paper), successful handovers only. d_z = mean difference / SD of the "
            "differences; d_av = mean "
            "difference / mean of the two SDs. Success rate: dynamic "
            f"{c['success']['dynamic']:.0%}, static {c['success']['static']:.0%}."
        ),
        "",
        (
            "What makes the comfort difference (mean over participants of static − dynamic cost, "
            "comfort points; "
            "positive favours dynamic): "
            + ", ".join(f"{k} {v:+.2f}" for k, v in c["cost_difference"].items())
            + f"; total {sum(c['cost_difference'].values()):+.2f}."
        ),
        "",
        "## H3 — optimised Θ̂ vs Θ uniform in the paper's ranges (A/B)",
        "",
        "| | choices preferring optimised | share | two-tailed binomial p | Cohen's h |",
        "|---|---|---|---|---|",
        f"| ours | {h3['k']} / {h3['n']} | {h3['share']:.1%} | {_p(h3['p'])} | {h3['h']:.2f} |",
        f"| paper | {PAPER['h3_k']} / {PAPER['h3_n']} | {PAPER['h3_share']:.1%} | {PAPER['h3_p']} "
        f"| {PAPER['h3_h']} |",
        "",
    ]
    if result.personal:
        lines += _personal_lines(result)
    t = result.timings
    n_unstable = sum(r["outcome"] == "unstable" for r in result.trials)
    lines += [
        (
            "Episodes the env ended as `unstable` (MuJoCo reset a diverging simulation; not "
            "rated, and "
            f"their A/B pairs not asked): {n_unstable} of {len(result.trials)} H1/H2 trials, "
            f"{result.unjudged} A/B pairs."
        ),
        "",
    ]
    lines += [
        "## Cost",
        "",
        (
            f"{t.get('episodes', 0):.0f} episodes ({t.get('episode_s', 0):.0f} s of env time); "
            "pooled CoSpar "
            f"{t.get('pooled_cospar_s', 0):.0f} s, H1/H2 {t.get('h1_h2_s', 0):.0f} s, H3 "
            f"{t.get('h3_s', 0):.0f} s, "
            f"personalised {t.get('personalised_s', 0):.0f} s; total {t.get('total_s', 0):.0f} s."
        ),
        "",
    ]
    return "\n".join(lines)


def _personal_lines(result: StudyResult) -> list[str]:
    rows = result.personal
    wins = sum(r["prefers_own"] for r in rows)
    n = sum(r["comparisons"] for r in rows)
    better = sum(r["u_own"] > r["u_population"] for r in rows)
    lines = [
        "## Personalised Θ (beyond the paper: its stated limitation, height and walking speed)",
        "",
        (
            "Each participant's own CoSpar Θ̂ against the population Θ̂ on "
            f"{rows[0]['comparisons']} held-out walks: "
            f"own preferred in **{wins} / {n}** choices ({wins / n:.0%}); own Θ̂ gives the higher "
            "mean "
            f"satisfaction for **{better} / {len(rows)}** participants."
        ),
        "",
        (
            "| participant | sex | height (m) | speed (m/s) | own Θ̂ | prefers own | u own | u "
            "population | "
            "success own / pop | time own / pop (s) | pull own / pop (N) | reach own / pop (m) |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted(rows, key=lambda r: r["height"]):
        own = HandoverParams(*(r[f"own_{n}"] for n in THETA_NAMES))
        lines.append(
            f"| {r['participant']} | {r['sex']} | {r['height']:.2f} | {r['speed']:.2f} | "
            f"{theta_line(own)} | "
            f"{r['prefers_own']}/{r['comparisons']} | {r['u_own']:.2f} | {r['u_population']:.2f} | "
            f"{r['own_success_rate']:.0%} / {r['pop_success_rate']:.0%} | "
            f"{r['own_handover_time']:.2f} / "
            f"{r['pop_handover_time']:.2f} | {r['own_pull_force']:.1f} / "
            f"{r['pop_pull_force']:.1f} | "
            f"{r['own_reach_distance']:.2f} / {r['pop_reach_distance']:.2f} |"
        )
    if len(rows) >= 3:
        h = np.array([r["height"] for r in rows])
        v = np.array([r["speed"] for r in rows])
        gain = np.array([r["u_own"] - r["u_population"] for r in rows])
        tf = np.array([r["own_forecast_time"] for r in rows])
        lines += [
            "",
            (
                f"Correlation over participants: gain of own over population utility vs height "
                f"{_corr(h, gain)}, vs speed {_corr(v, gain)}; own t_f vs speed {_corr(v, tf)}; "
                "own t_f vs "
                f"height {_corr(h, tf)} (Pearson r; few participants, indicative only)."
            ),
        ]
    return lines + [""]


def _corr(a: np.ndarray, b: np.ndarray) -> str:
    if np.std(a) == 0 or np.std(b) == 0:
        return "r = –"
    return f"r = {float(np.corrcoef(a, b)[0, 1]):+.2f}"


def study_figure(result: StudyResult) -> Any:
    """Comfort and time, dynamic vs static; H3 choices; personalised gain against height."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = result.h1_h2
    fig, axes = plt.subplots(
        1, 3 if result.personal else 2, figsize=(13 if result.personal else 8.5, 3.6)
    )
    for ax, key, per, unit in ((axes[0], "comfort", c["comfort_per_participant"], "Likert"),
                               (axes[1], "time", c["time_per_participant"], "s")):
        conds = ("dynamic", "static")
        ours = [np.nanmean(per[k]) for k in conds]
        sds = [np.nanstd(per[k], ddof=1) for k in conds]
        paper = [PAPER[f"{key}_{k}"] for k in conds]
        x = np.arange(2)
        ax.bar(
            x - 0.2,
            ours,
            0.4,
            yerr=sds,
            color=["C0", "C1"],
            alpha=0.8,
            capsize=4,
            label="simulated",
        )
        ax.bar(
            x + 0.2,
            [m for m, _ in paper],
            0.4,
            yerr=[s for _, s in paper],
            color="0.75",
            capsize=4,
            label="paper (people)",
        )
        for i, k in enumerate(conds):
            ax.plot(np.full(len(per[k]), i - 0.2), per[k], "k.", alpha=0.6)
        ax.set_xticks(x, conds)
        ax.set_ylabel(f"{'comfort' if key == 'comfort' else 'handover time'} ({unit})")
        ax.legend(fontsize=7)
    if result.personal:
        ax = axes[2]
        h = [r["height"] for r in result.personal]
        gain = [r["u_own"] - r["u_population"] for r in result.personal]
        sc = ax.scatter(h, gain, c=[r["speed"] for r in result.personal], cmap="viridis")
        ax.axhline(0, color="0.5", lw=0.8)
        ax.set_xlabel("height (m)")
        ax.set_ylabel("utility own Θ̂ − population Θ̂")
        fig.colorbar(sc, ax=ax, label="walking speed (m/s)")
    fig.suptitle("User study with simulated participants (not people)", fontsize=10)
    fig.tight_layout()
    return fig


def write_report(result: StudyResult, out: Path) -> list[Path]:
    """user_study.md, summary.json, trials.csv, h3_choices.csv, personalised.csv, participants.csv,
    PNG, and the pooled CoSpar run in ``pooled/`` (:func:`.tuning_report.save_run`)."""
    out.mkdir(parents=True, exist_ok=True)
    if result.pooled is not None and result.pooled_config is not None:
        save_run(result.pooled, result.participants, result.pooled_config, out / "pooled")
    text = markdown(result)
    write_text(text, out / "user_study.md")
    write_csv(result.trials, out / "trials.csv")
    write_csv(result.choices, out / "h3_choices.csv")
    if result.personal:
        write_csv(result.personal, out / "personalised.csv")
    write_csv([p.describe() for p in result.participants], out / "participants.csv")
    summary: dict[str, Any] = {
        "source": "simulated participants (agents/participants.py), not people",
        "theta_population": dict(zip(THETA_NAMES, result.theta_pop.as_array())),
        "h1_comfort": result.h1_h2["comfort"],
        "h2_time": result.h1_h2["time"],
        "success": result.h1_h2["success"],
        "cost_difference": result.h1_h2["cost_difference"],
        "h3": result.h3,
        "timings": result.timings,
    }
    write_text(json.dumps(summary, indent=1, default=float), out / "summary.json")
    write_png(study_figure(result), out / "user_study.png", dpi=110)
    print(text)
    return [out / "user_study.md", out / "user_study.png"]
