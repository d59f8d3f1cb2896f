"""Acceptance check "CoSpar learns": its Theta-hat against the optimum brute-forced over a grid.

For each checked participant every Theta of a small grid over the paper's ranges (3^4 = 81 by
default) is run on the participant's walks (episodes cached in ``episodes.jsonl``, so a rerun
costs nothing), giving their utility u(Theta) = mean satisfaction over the walks
(:meth:`agents.participants.Participant.utility`). CoSpar then runs on the same grid for 20
iterations, the participant answering with their probit noise from the same episodes. The score
is the share of the achievable gain over a random Theta that CoSpar's Theta-hat reaches::

    gain = (u(Theta-hat) - mean_grid u) / (max_grid u - mean_grid u)

(``mean_grid u`` is the expected utility of a Theta drawn uniformly from the grid). The check
passes for a participant at gain >= 0.9; the acceptance asks for 3 of 4.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.cospar import THETA_NAMES, CoSparConfig, action_grid
from agents.participants import sample_population
from handover_env.config import HandoverParams
from handover_eval.preference.tuning import (
    EpisodeRunner,
    PreferenceConfig,
    lived,
    run_preference,
)
from handover_eval.preference.tuning_report import theta_line
from handover_eval.reporting import write_csv, write_text

PASS_GAIN = 0.9


@dataclass(frozen=True)
class CheckConfig:
    """Settings of the brute-force check (see the module docstring)."""

    participants: int = 4
    population_seed: int = 1
    grid: tuple[int, int, int, int] = (3, 3, 3, 3)
    walks: int = 3
    iterations: int = 20
    seed: int = 0
    agent: str = "ours"
    receiver: str = "id"
    sensing: str = "paper"


def load_episode_cache(runner: EpisodeRunner, path: Path) -> None:
    """Fill ``runner``'s episode cache from ``path`` (JSON lines), only with the episodes of
    ``runner``'s sensing profile (a line without one is from before the profiles: ideal)."""
    if path.exists():
        for line in path.read_text().splitlines():
            rec = json.loads(line)
            if rec.get("sensing", "ideal") != runner.sensing:  # lines before profiles: ideal
                continue
            key = rec["key"]
            runner.cache[tuple(key[:-1]) + (tuple(key[-1]),)] = rec["info"]


def save_episode_cache(runner: EpisodeRunner, path: Path) -> None:
    """Write ``runner``'s episode cache to ``path`` (JSON lines, each with its sensing profile)."""
    write_text("".join(json.dumps({"key": list(key[:-1]) + [list(key[-1])], "info": info,
                                   "sensing": runner.sensing}) + "\n"
                       for key, info in runner.cache.items()), path)


def run_check(config: CheckConfig, out: Path, progress: bool = True,
              runner: EpisodeRunner | None = None) -> list[dict[str, Any]]:
    """Brute force, then CoSpar, per participant; writes check.csv/check.md to ``out``."""
    from tqdm import tqdm

    participants = sample_population(config.participants, config.population_seed, male_fraction=0.5)
    runner = runner or EpisodeRunner(config.agent, config.receiver, sensing=config.sensing)
    cache = out / "episodes.jsonl"
    load_episode_cache(runner, cache)
    cospar = CoSparConfig(points_per_dim=config.grid)
    grid = action_grid(cospar)
    utilities: dict[int, np.ndarray] = {}
    try:
        for p in participants:
            seeds = p.walk_seeds(config.walks, 0)
            bar = tqdm(
                grid, desc=f"brute force, participant {p.pid}", unit="Θ", disable=not progress
            )
            utilities[p.pid] = np.array(
                [p.utility(lived(runner.run(p, HandoverParams(*g), seeds))) for g in bar]
            )
    finally:
        save_episode_cache(runner, cache)
    rows = []
    for p in participants:
        u = utilities[p.pid]
        result = run_preference(
            [p],
            PreferenceConfig(
                iterations=config.iterations, walks=config.walks, cospar=cospar, seed=config.seed
            ),
            runner=runner,
            judge=lambda q, a: float(utilities[q.pid][a]),
        )
        hat = result.learner.best_index()
        best = int(np.argmax(u))
        gain = float((u[hat] - u.mean()) / (u[best] - u.mean())) if u[best] > u.mean() else 1.0
        rows.append({
            "participant": p.pid, "height": p.body.height, "speed": p.body.speed,
            **{f"best_{n}": grid[best][k] for k, n in enumerate(THETA_NAMES)},
            **{f"hat_{n}": grid[hat][k] for k, n in enumerate(THETA_NAMES)},
            "u_best": float(u[best]), "u_random": float(u.mean()), "u_hat": float(u[hat]),
            "rank_of_hat": int(np.sum(u > u[hat])) + 1, "gain": gain, "passed": gain >= PASS_GAIN,
        })
    write_csv(rows, out / "check.csv")
    passed = sum(r["passed"] for r in rows)
    lines = [
        f"# CoSpar learns: Θ̂ after {config.iterations} iterations vs the brute-forced optimum "
        "(simulated participants)",
        "",
        (
            f"Grid {'x'.join(map(str, config.grid))} = {len(grid)} Θ over the paper's ranges, "
            f"{config.walks} walks each, "
            f"agent {config.agent}, receiver {config.receiver}. gain = (u(Θ̂) − mean u) / (max u "
            "− mean u); "
            f"pass at ≥ {PASS_GAIN:.0%}."
        ),
        "",
        "| participant | height (m) | speed (m/s) | best Θ | u best | u random | CoSpar Θ̂ | u Θ̂ "
        "| rank | gain | pass |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        best = HandoverParams(*(r[f"best_{n}"] for n in THETA_NAMES))
        hat = HandoverParams(*(r[f"hat_{n}"] for n in THETA_NAMES))
        lines.append(
            f"| {r['participant']} | {r['height']:.2f} | {r['speed']:.2f} | {theta_line(best)} | "
            f"{r['u_best']:.2f} | {r['u_random']:.2f} | {theta_line(hat)} | {r['u_hat']:.2f} | "
            f"{r['rank_of_hat']}/{len(grid)} | {r['gain']:.0%} | {'yes' if r['passed'] else 'no'} |"
        )
    lines += [
        "",
        (
            f"**{passed} of {len(rows)} participants reach ≥ {PASS_GAIN:.0%} of the achievable "
            "gain** "
            f"(acceptance: ≥ 3 of 4). Episodes run now: {runner.episodes_run} "
            f"({runner.seconds:.0f} s); "
            f"cached in `{cache.name}`."
        ),
    ]
    write_text("\n".join(lines) + "\n", out / "check.md")
    print("\n".join(lines))
    return rows
