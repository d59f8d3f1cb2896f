"""The paper's user study (Sec. V-B) with simulated participants: H1, H2, H3, and personalised
Theta.

``python evaluate.py user-study --participants 8 --trials 5`` runs, for a population drawn by
:func:`agents.participants.sample_population` (75 % male, as the paper's 6 of 8):

1. **Population Theta-hat.** CoSpar pooled over all participants (:mod:`.tuning`), 20
   iterations, on their tuning walks (walk stream 0): one Theta-hat, as the paper learned one.
2. **H1/H2.** Each participant does ``trials`` dynamic handovers (``ours`` with the population
   Theta-hat, DynamicHandover-v0) and ``trials`` static ones (the static agent, StaticHandover-v0,
   with the same K, B, f_r) on the same walks (stream 1), answering Q1 after each (Likert, the
   participant's ordered-probit mapping). Per participant the trial averages are taken (the paper:
   "individual trial averages were used"); comfort and handover time (``info["handover_time"]``,
   the 2 s stabilisation delay excluded as in the paper; failed handovers have none) are reported
   as M ± SD over participants, with a paired t-test and Cohen's d (d_z = mean difference / SD of
   the differences; d_av = mean difference / mean of the two SDs, Lakens 2013).
3. **H3.** Each participant does ``trials`` A/B tests on their study walks: one handover with the
   population Theta-hat and one with Theta drawn uniformly from the paper's ranges, then says which
   was more satisfactory (Eq. 2 noise). Share preferring optimised, two-tailed binomial p against
   50 %, Cohen's h = 2 asin(sqrt(p)) - 2 asin(sqrt(0.5)).
4. **Personalised Theta** (beyond the paper; its stated limitation). CoSpar per participant
   (same settings, their tuning walks) gives their own Theta-hat; on ``trials`` held-out walks
   (stream 2) they compare their own against the population Theta-hat: preference share, and the
   outcome measures and hidden utility under each, listed with height and walking speed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.cospar import THETA_NAMES, CoSparConfig
from agents.participants import COST_NAMES, Participant, sample_population
from handover_env.config import THETA_RANGES, HandoverParams
from handover_eval.backend import map_jobs
from handover_eval.preference.tuning import (
    EpisodeRunner,
    PreferenceConfig,
    PreferenceResult,
    run_preference,
    summarise_outcomes,
)

#: The paper's figures (Sec. V-B-2, V-B-3), shown beside ours.
PAPER = {
    "comfort_dynamic": (4.3, 0.45),
    "comfort_static": (3.1, 0.87),
    "comfort_p": "< 0.01",
    "comfort_d": 0.79,
    "time_dynamic": (3.2, 0.50),
    "time_static": (6.9, 1.2),
    "time_p": "< 0.001",
    "time_d": 1.92,
    "h3_share": 0.725,
    "h3_k": 29,
    "h3_n": 40,
    "h3_p": "< 0.01",
    "h3_h": 0.47,
}
UNSTABLE = "unstable"
#: Walk-seed streams of a participant (never overlapping).
TUNING, STUDY, HELD_OUT = 0, 1, 2


@dataclass(frozen=True)
class StudyConfig:
    """Settings of the simulated user study.

    Args:
        participants: how many (the paper: 8).
        trials: handovers per condition and A/B tests per participant (the paper: 5).
        iterations: CoSpar iterations, pooled and per participant (the paper: 20).
        walks: tuning walks per proposed Theta.
        grid: CoSpar grid points per parameter.
        seed: population seed (participant i has seed 1000 * seed + i); also seeds CoSpar and the
            random Theta of H3.
        theta: skip the pooled CoSpar run and use this population Theta-hat (K, B, t_f, f_r).
        personalised: run the per-participant CoSpar and comparison.
        agent: the planner whose Theta is tuned.
        sensing: the env's sensing profile (``"paper"``, the env's default; docs/sensing.md).
        workers: processes running the per-participant CoSpar (part 4) in parallel (1: in this
            process); with the Ray backend (:mod:`.backend`) they are Ray tasks. Same results.
    """

    participants: int = 8
    trials: int = 5
    iterations: int = 20
    walks: int = 3
    grid: tuple[int, int, int, int] = (7, 6, 6, 7)
    seed: int = 0
    theta: tuple[float, float, float, float] | None = None
    personalised: bool = True
    agent: str = "ours"
    sensing: str = "paper"
    workers: int = 1

    def __post_init__(self) -> None:
        if self.participants < 2 or self.trials < 1:
            raise ValueError(f"need >= 2 participants (paired tests) and >= 1 trial, got "
                             f"{self.participants}, {self.trials}")
        if self.theta is not None:
            HandoverParams(*self.theta)
        if self.workers < 1:
            raise ValueError(f"--workers must be >= 1, got {self.workers}")


@dataclass
class StudyResult:
    """Everything the report needs."""

    config: StudyConfig
    participants: list[Participant]
    theta_pop: HandoverParams
    trials: list[dict[str, Any]] = field(default_factory=list)
    h1_h2: dict[str, Any] = field(default_factory=dict)
    choices: list[dict[str, Any]] = field(default_factory=list)
    h3: dict[str, Any] = field(default_factory=dict)
    personal: list[dict[str, Any]] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    unjudged: int = 0
    #: The pooled CoSpar run that gave ``theta_pop`` and its settings (None with ``--theta``).
    pooled: PreferenceResult | None = None
    pooled_config: PreferenceConfig | None = None
    #: The walkers every episode met: ``"id"`` / ``"ood"`` scripted walkers or ``"replay"``.
    receiver: str = "id"
    #: The env's sensing profile of every episode (the runner's).
    sensing: str = "paper"


# ---------------------------------------------------------------------------- statistics
def paired_stats(a: Sequence[float], b: Sequence[float]) -> dict[str, float]:
    """M ± SD of each, paired t-test p (two-sided), Cohen's d_z and d_av (Lakens 2013), on pairs
    where both are finite."""
    from scipy import stats

    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    out = {"n": int(ok.sum()), "mean_a": float(np.mean(x)) if x.size else math.nan,
           "sd_a": float(np.std(x, ddof=1)) if x.size > 1 else math.nan,
           "mean_b": float(np.mean(y)) if y.size else math.nan,
           "sd_b": float(np.std(y, ddof=1)) if y.size > 1 else math.nan}
    diff = x - y
    sd_diff = float(np.std(diff, ddof=1)) if diff.size > 1 else math.nan
    out["mean_diff"] = float(np.mean(diff)) if diff.size else math.nan
    if diff.size > 1 and sd_diff > 0:
        out["p"] = float(stats.ttest_rel(x, y).pvalue)
        out["d_z"] = out["mean_diff"] / sd_diff
    else:
        out["p"] = 0.0 if diff.size > 1 and out["mean_diff"] != 0 else math.nan
        out["d_z"] = math.copysign(math.inf, out["mean_diff"]) if out["p"] == 0.0 else math.nan
    sd_av = 0.5 * (out["sd_a"] + out["sd_b"])
    out["d_av"] = out["mean_diff"] / sd_av if sd_av > 0 else math.nan
    return out


def binomial_stats(k: int, n: int) -> dict[str, float]:
    """Share, two-tailed binomial p against 1/2, Cohen's h against 1/2."""
    from scipy import stats

    share = k / n if n else math.nan
    return {
        "k": k,
        "n": n,
        "share": share,
        "p": float(stats.binomtest(k, n, 0.5).pvalue) if n else math.nan,
        "h": 2 * math.asin(math.sqrt(share)) - 2 * math.asin(math.sqrt(0.5)) if n else math.nan,
    }


def _reseed(people: Sequence[Participant], stream: int) -> None:
    """Each part of the study draws its answer noise from its own stream: a run with ``--theta``
    set to the pooled Theta-hat reproduces H1-H3 exactly."""
    for p in people:
        p.reseed(stream)


def _cost_difference(
    trials: Sequence[dict[str, Any]], people: Sequence[Participant]
) -> dict[str, float]:
    """Mean over participants of (static - dynamic) per cost term, comfort points: what each term
    contributes to the dynamic condition's advantage (negative: it favours static)."""
    out = {}
    for name in COST_NAMES:
        diffs = []
        for p in people:
            rows = {
                c: [
                    r[f"cost_{name}"]
                    for r in trials
                    if r["participant"] == p.pid and r["condition"] == c
                ]
                for c in ("dynamic", "static")
            }
            diffs.append(float(np.nanmean(rows["static"]) - np.nanmean(rows["dynamic"])))
        out[name] = float(np.nanmean(diffs))
    return out


def random_theta(rng: np.random.Generator) -> HandoverParams:
    """Theta uniform in the paper's ranges (H3's unoptimised system)."""
    return HandoverParams(*(float(rng.uniform(*THETA_RANGES[n])) for n in THETA_NAMES))


@dataclass(frozen=True)
class _PersonalJob:
    """Part 4 for one participant (their answer noise already on its own stream)."""

    participant: Participant
    pcfg: PreferenceConfig
    theta_pop: HandoverParams
    trials: int


def _personal(
    runner: EpisodeRunner, job: _PersonalJob
) -> tuple[dict[str, Any] | None, int, int, float]:
    """CoSpar on one participant, then their own Theta-hat against the population's on held-out
    walks. Returns (row or None, unjudged pairs, episodes run, their seconds)."""
    p, theta_pop = job.participant, job.theta_pop
    episodes, seconds = runner.episodes_run, runner.seconds
    own = run_preference([p], job.pcfg, runner=runner).theta_hat
    seeds = p.walk_seeds(job.trials, HELD_OUT)
    pairs = [(x, y) for x, y in zip(runner.run(p, own, seeds), runner.run(p, theta_pop, seeds))
             if UNSTABLE not in (x["outcome"], y["outcome"])]
    done = (len(seeds) - len(pairs), runner.episodes_run - episodes, runner.seconds - seconds)
    if not pairs:
        return (None, *done)
    a, b = [x for x, _ in pairs], [y for _, y in pairs]
    wins = sum(p.prefers(p.satisfaction(x), p.satisfaction(y)) for x, y in zip(a, b))
    oa, ob = summarise_outcomes(a), summarise_outcomes(b)
    return ({
        "participant": p.pid, "sex": p.body.sex, "height": p.body.height, "speed": p.body.speed,
        "pass_y": p.body.pass_y, **{f"own_{n}": v for n, v in zip(THETA_NAMES, own.as_array())},
        "prefers_own": wins, "comparisons": len(pairs),
        "u_own": p.utility(a), "u_population": p.utility(b),
        **{f"own_{k2}": v for k2, v in oa.items()}, **{f"pop_{k2}": v for k2, v in ob.items()},
    }, *done)


# ---------------------------------------------------------------------------- the study
def run_study(config: StudyConfig, progress: bool = True,
              runner: EpisodeRunner | None = None) -> StudyResult:
    """Run every part and return the values; :func:`.study_report.write_report` writes them."""
    from tqdm import tqdm

    t_start = time.perf_counter()
    people = sample_population(config.participants, config.seed)
    runner = runner or EpisodeRunner(config.agent, "id", sensing=config.sensing)
    cospar = CoSparConfig(points_per_dim=config.grid)
    pcfg = PreferenceConfig(iterations=config.iterations, walks=config.walks, agent=config.agent,
                            sensing=config.sensing, cospar=cospar, seed=config.seed,
                            walk_stream=TUNING)
    timings: dict[str, float] = {}
    # 1. population Theta-hat
    t0 = time.perf_counter()
    _reseed(people, 10)
    pooled = None
    if config.theta is None:
        pooled = run_preference(people, pcfg, runner=runner, progress=progress)
        theta_pop = pooled.theta_hat
    else:
        theta_pop = HandoverParams(*config.theta)
    timings["pooled_cospar_s"] = time.perf_counter() - t0
    result = StudyResult(config, people, theta_pop, pooled=pooled, pooled_config=pcfg,
                         receiver=runner.receiver, sensing=runner.sensing)
    # 2. H1/H2
    t0 = time.perf_counter()
    _reseed(people, 11)
    for p in tqdm(people, desc="H1/H2 dynamic vs static", unit="participant", disable=not progress):
        for t, seed in enumerate(p.walk_seeds(config.trials, STUDY)):
            for cond, static in (("dynamic", False), ("static", True)):
                info = runner.run(p, theta_pop, [seed], static=static)[0]
                judged = info["outcome"] != UNSTABLE  # a numerical event is not rated (see lived())
                result.trials.append(
                    {
                        "participant": p.pid,
                        "trial": t,
                        "condition": cond,
                        "walk_seed": seed,
                        "outcome": info["outcome"],
                        "handover_time": info.get("handover_time"),
                        "handover_time_with_delay": info.get("handover_time_with_delay"),
                        "likert": p.likert(info) if judged else math.nan,
                        "satisfaction": p.satisfaction(info) if judged else math.nan,
                        **{
                            f"cost_{k}": v if judged else math.nan for k, v in p.costs(info).items()
                        },
                    }
                )
    per = {cond: [] for cond in ("dynamic", "static")}
    times = {cond: [] for cond in ("dynamic", "static")}
    for p in people:
        for cond, ratings in per.items():
            rows = [
                r for r in result.trials if r["participant"] == p.pid and r["condition"] == cond
            ]
            rated = [r["likert"] for r in rows if math.isfinite(r["likert"])]
            ratings.append(float(np.mean(rated)) if rated else math.nan)
            ok = [r["handover_time"] for r in rows if r["handover_time"] is not None]
            times[cond].append(float(np.mean(ok)) if ok else math.nan)
    result.h1_h2 = {"comfort": paired_stats(per["dynamic"], per["static"]),
                    "cost_difference": _cost_difference(result.trials, people),
                    "time": paired_stats(times["static"], times["dynamic"]),
                    "comfort_per_participant": per, "time_per_participant": times,
                    "success": {c: float(np.mean([r["outcome"] == "success" for r in result.trials
                                                  if r["condition"] == c])) for c in per}}
    timings["h1_h2_s"] = time.perf_counter() - t0
    # 3. H3
    t0 = time.perf_counter()
    _reseed(people, 12)
    for p in tqdm(people, desc="H3 optimised vs random", unit="participant", disable=not progress):
        rng = np.random.default_rng(np.random.SeedSequence([config.seed, p.pid, 3]))
        for t, seed in enumerate(p.walk_seeds(config.trials, STUDY)):
            theta_r = random_theta(rng)
            opt = runner.run(p, theta_pop, [seed])[0]
            rnd = runner.run(p, theta_r, [seed])[0]
            if UNSTABLE in (opt["outcome"], rnd["outcome"]):
                result.unjudged += 1
                continue
            u_opt, u_rnd = p.satisfaction(opt), p.satisfaction(rnd)
            result.choices.append(
                {
                    "participant": p.pid,
                    "trial": t,
                    "walk_seed": seed,
                    **{f"random_{n}": v for n, v in zip(THETA_NAMES, theta_r.as_array())},
                    "optimised_outcome": opt["outcome"],
                    "random_outcome": rnd["outcome"],
                    "u_optimised": u_opt,
                    "u_random": u_rnd,
                    "prefers_optimised": p.prefers(u_opt, u_rnd),
                }
            )
    k = sum(c["prefers_optimised"] for c in result.choices)
    result.h3 = binomial_stats(k, len(result.choices))
    timings["h3_s"] = time.perf_counter() - t0
    # 4. personalised: one job per participant (:mod:`.backend`), the runner (its fitted planner
    # and episode cache) sent to each worker once
    t0 = time.perf_counter()
    _reseed(people, 13)
    episodes, episode_s = runner.episodes_run, runner.seconds  # parts 1-3; part 4's jobs add theirs
    if config.personalised:
        jobs = [_PersonalJob(p, pcfg, theta_pop, config.trials) for p in people]
        for row, unjudged, n, seconds in map_jobs(
            _personal,
            runner,
            jobs,
            workers=config.workers,
            progress=progress,
            desc="personalised CoSpar",
            unit="participant",
            label=lambda job: f"participant {job.participant.pid}",
        ):
            result.unjudged += unjudged
            episodes, episode_s = episodes + n, episode_s + seconds
            if row is not None:
                result.personal.append(row)
    timings["personalised_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - t_start
    timings["episodes"] = episodes
    timings["episode_s"] = episode_s
    result.timings = timings
    return result
