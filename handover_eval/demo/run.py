"""The demo's episodes: one seeded walker meets the dynamic agent and the static baseline.

The paper's user study (Sec. V-C, H2) asks whether a robot that hands the object over while the
person keeps walking (dynamic handover) is faster than the static handover of Meng et al. 2022,
where the person stops in a predefined area, raises a hand and waits while the robot detects it,
waits 2 s for the detection to settle and delivers. Here the same seeded scripted walker (an ID
walker, ``reset(seed=s, options={"receiver": "id"})``) meets

* the SPGP planner ("ours", :class:`agents.nonparametric.NonparametricAgent` fitted on the
  embedded synthetic default) in ``handover_env/DynamicHandover-v0``, and
* the static baseline (:class:`agents.static.StaticAgent`) in ``handover_env/StaticHandover-v0``,

both at the env's default Θ-hat. The seed draws the same person in both envs (height, speed,
start and the shape of the walk); the static task replaces only the end of the path and its
passing line with its stop area. Each episode is scored as the benchmark scores one (the closed
loop's row, :func:`handover_eval.episodes.episode_row`, and the outcome and first
failure of :mod:`handover_eval.benchmark.outcomes`). The episodes of :data:`VIDEO_SEEDS` are also
filmed: every :data:`FRAME_STRIDE`-th env step and the final state, through
:class:`handover_eval.demo.view.FramedView`, with the facts each caption shows
(:class:`Moment`).

The seeds (:data:`DEMO_SEEDS`) were fixed when this module was written, before any of their
episodes had been run; they lie in the development range (below
:data:`handover_eval.benchmark.protocol.TRAIN_SEED_LIMIT`), never the benchmark's test seeds.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

import handover_env  # noqa: F401 - registers the envs
from agents.base import Agent
from agents.nonparametric import NonparametricAgent
from agents.static import StaticAgent
from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout
from handover_env.person.demos import load_any
from handover_eval.benchmark.outcomes import events, first_failure
from handover_eval.demo.view import FramedView, ViewSize
from handover_eval.episodes import Played, episode_row
from handover_eval.episodes import play as play_episode
from handover_eval.receivers import ReceiverSpec

#: The six walkers of the summary, fixed before any of their episodes was run (issue 37).
DEMO_SEEDS: tuple[int, ...] = (37_000, 37_001, 37_002, 37_003, 37_004, 37_005)
#: The walkers filmed side by side: the first of :data:`DEMO_SEEDS` (also fixed in advance).
VIDEO_SEEDS: tuple[int, ...] = DEMO_SEEDS[:1]
#: The receiver kind every walker is drawn from (the scripted in-distribution walker).
RECEIVER = "id"
#: Film every second env step: 15 frames per simulated second, played back in real time.
FRAME_STRIDE = 2
ENV_STEP_S = 1.0 / 30.0


@dataclass(frozen=True)
class Side:
    """One side of the comparison: its key, the caption's name for the agent, and its env."""

    key: str
    agent_label: str
    env_id: str


SIDES: tuple[Side, Side] = (
    Side("dynamic", "Dynamic: SPGP planner (ours)", "handover_env/DynamicHandover-v0"),
    Side("static", "Static baseline (stop, raise hand, 2 s)", "handover_env/StaticHandover-v0"),
)


@dataclass(frozen=True)
class Moment:
    """What a caption shows at one filmed step.

    Attributes:
        time: s since the reset (the env's ``info["time"]``).
        wrist_force: N, magnitude of the measured wrist force (the observation's ``wrist_force``).
        release_time: s when the gripper opened, None before.
        robot_enabled: False while the static robot still waits for the hand and the delay.
        outcome: the env's outcome at that step ("running" until the episode ends).
    """

    time: float
    wrist_force: float
    release_time: float | None
    robot_enabled: bool
    outcome: str


@dataclass
class DemoEpisode:
    """One side's episode with one walker.

    Attributes:
        side: the :class:`Side` key.
        seed: the walker's reset seed.
        info: the env's final ``info``.
        row: the benchmark's scoring of it: ``outcome`` (``"timeout"`` when the time ran out),
            ``success``, ``first_failure`` ("" for a success), ``handover_time`` and
            ``handover_time_with_delay`` (s, NaN unless a success), ``release_force``,
            ``peak_wrist_force``, ``body_contact_force``, ``steps``.
        frames: the filmed RGB frames (empty unless filmed).
        moments: one :class:`Moment` per frame.
        wall: s of wall time for the episode.
    """

    side: str
    seed: int
    info: dict[str, Any]
    row: dict[str, Any]
    frames: list[np.ndarray] = field(default_factory=list)
    moments: list[Moment] = field(default_factory=list)
    wall: float = 0.0


class _LastObservation(gym.Wrapper):
    """Keeps the observation of the latest ``reset``/``step`` (the caption's wrist force)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.last_obs: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict]:
        obs, info = self.env.reset(**kwargs)
        self.last_obs = obs
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.last_obs = obs
        return obs, reward, terminated, truncated, info


@dataclass(frozen=True)
class DemoSetting:
    """What the closed loop's row says of a demo episode besides the walker and the outcome (a
    :class:`handover_eval.episodes.RowSource`): the side's key as the agent, Θ-hat, no model
    fold."""

    agent: str
    env: str
    params: HandoverParams = field(default_factory=HandoverParams)
    env_kwargs: str = ""
    hand_mode: str = "reach"
    model_fold: int | None = None
    extra: tuple[tuple[str, Any], ...] = ()


def benchmark_row(side: str, seed: int, played: Played) -> dict[str, Any]:
    """The benchmark's scoring of one episode: the closed loop's row of its final ``info``
    (:func:`handover_eval.episodes.episode_row`), then the outcome, success and first failure of
    :mod:`handover_eval.benchmark.outcomes`."""
    spec = ReceiverSpec(set=RECEIVER, key=f"{RECEIVER}-{seed}", seed=seed)
    full = episode_row(DemoSetting(side, side), spec, played.info, played.steps, played.wall_s)
    full["sim_unstable"] = played.sim_unstable
    ff = first_failure(str(full["outcome"]), events(full))
    return {
        "side": side,
        "seed": seed,
        "outcome": full["outcome"],
        "success": ff == "",
        "first_failure": ff,
        "handover_time": full["handover_time"],
        "handover_time_with_delay": full["handover_time_with_delay"],
        "release_force": full["release_force"],
        "peak_wrist_force": full["peak_wrist_force"],
        "body_contact_force": full["body_contact_force"],
        "steps": played.steps,
    }


def _moment(info: dict[str, Any], obs: np.ndarray | None, layout: ObsLayout) -> Moment:
    parts = layout.unflatten(obs) if obs is not None else None
    force = float(np.linalg.norm(parts["wrist_force"])) if parts is not None else 0.0
    enabled = bool(parts["robot_enabled"][0] > 0.5) if parts is not None else True
    return Moment(float(info.get("time", 0.0)), force, info.get("release_time"), enabled,
                  str(info.get("outcome", "running")))


def play(env: gym.Env, agent: Agent, side: str, seed: int,
         film: Callable[[], np.ndarray] | None = None) -> DemoEpisode:
    """Run one episode of ``agent`` with walker ``seed`` in ``env`` (a :class:`_LastObservation`
    wrapped handover env); film it when ``film`` (a renderer of the env's current state) is
    given."""
    assert isinstance(env, _LastObservation)
    layout = ObsLayout()
    frames: list[np.ndarray] = []
    moments: list[Moment] = []
    filmed = [-1]

    def on_step(step: int, info: dict) -> None:
        if film is not None and step % FRAME_STRIDE == 0:
            frames.append(film())
            moments.append(_moment(info, env.last_obs, layout))
            filmed[0] = step

    played = play_episode(env, agent, seed, {"receiver": RECEIVER}, on_step)
    if film is not None and filmed[0] != played.steps - 1:  # the final state, once
        frames.append(film())
        moments.append(_moment(played.info, env.last_obs, layout))
    row = benchmark_row(side, seed, played)
    return DemoEpisode(side, seed, played.info, row, frames, moments, played.wall_s)


def make_env(side: Side) -> _LastObservation:
    """``side``'s env at the default Θ-hat, wrapped to keep its latest observation."""
    return _LastObservation(gym.make(side.env_id))


def fit_planner() -> NonparametricAgent:
    """The SPGP planner fitted on the embedded synthetic default (no data download)."""
    return NonparametricAgent().fit(load_any(None))


def run_side(side: Side, agent: Agent, seeds: Sequence[int],
             film_factory: Callable[[gym.Env], Callable[[], np.ndarray]] | None = None,
             video_seeds: Sequence[int] = (),
             on_episode: Callable[[DemoEpisode], None] | None = None) -> list[DemoEpisode]:
    """Every walker of ``seeds`` on ``side``; those in ``video_seeds`` filmed through
    ``film_factory(env)`` (None: nothing is filmed)."""
    env = make_env(side)
    film = film_factory(env) if film_factory is not None and video_seeds else None
    try:
        out = []
        for seed in seeds:
            ep = play(env, agent, side.key, int(seed), film if seed in video_seeds else None)
            if on_episode is not None:
                on_episode(ep)
            out.append(ep)
        return out
    finally:
        close = getattr(film, "close", None)
        if close is not None:
            close()
        env.close()


def handover_times(episodes: Sequence[DemoEpisode], key: str = "handover_time") -> list[float]:
    """The successes' handover times (s) of ``episodes``, in order."""
    return [float(e.row[key]) for e in episodes
            if e.row["success"] and math.isfinite(float(e.row[key]))]


@dataclass(frozen=True)
class DemoJob:
    """Walkers of one side run in one process: all of ``seeds``, those in ``film_seeds`` filmed."""

    side: str
    seeds: tuple[int, ...]
    film_seeds: tuple[int, ...] = ()
    size: ViewSize | None = None


def plan(seeds: Sequence[int], video_seeds: Sequence[int], film: bool,
         size: ViewSize | None = None) -> tuple[list[DemoJob], list[DemoJob]]:
    """(this process's jobs, the helper process's jobs). The static side's filmed walkers (its
    longest episodes, and most of the rendering) go to the helper; the planner's fit, the dynamic
    side and the static side's other walkers stay here. Without filming, the helper runs the
    whole static side."""
    seeds = tuple(int(s) for s in seeds)
    film_seeds = tuple(int(s) for s in video_seeds) if film else ()
    helper_seeds = tuple(s for s in seeds if s in film_seeds) or seeds
    static_rest = tuple(s for s in seeds if s not in helper_seeds)
    here = [DemoJob("dynamic", seeds, film_seeds, size)]
    if static_rest:
        here.append(DemoJob("static", static_rest, (), size))
    return here, [DemoJob("static", helper_seeds, film_seeds, size)]


def run_job(job: DemoJob, agent: Agent | None = None,
            on_episode: Callable[[DemoEpisode], None] | None = None) -> list[DemoEpisode]:
    """``job``'s episodes in this process (the dynamic side fits its planner unless ``agent``
    is given)."""
    side = next(s for s in SIDES if s.key == job.side)
    if agent is None:
        agent = fit_planner() if job.side == "dynamic" else StaticAgent()
    size = job.size
    factory = (lambda env: FramedView(env, size=size)) if job.film_seeds else None
    return run_side(side, agent, job.seeds, factory, job.film_seeds, on_episode)


@dataclass
class DemoRun:
    """The demo's episodes by side key (in :data:`SIDES` order, each in seed order), and the
    wall seconds spent fitting the planner and in all."""

    episodes: dict[str, list[DemoEpisode]]
    fit_s: float
    total_s: float


def run(seeds: Sequence[int] = DEMO_SEEDS, video_seeds: Sequence[int] = VIDEO_SEEDS,
        film: bool = True, size: ViewSize | None = None, workers: int = 2,
        on_episode: Callable[[DemoEpisode], None] | None = None,
        planner: Agent | None = None) -> DemoRun:
    """Run every walker of ``seeds`` on both sides; film the walkers of ``video_seeds`` when
    ``film``. With ``workers`` = 2 a spawned helper process runs its share of :func:`plan` while
    this one runs the rest; 1 runs everything here. Either way each episode is seeded and its
    agent reset, so the episodes are the same. Each process holds one GL context at a time (a
    side's view is closed before the next side starts). ``planner`` is the dynamic side's agent
    (default: :func:`fit_planner`'s; it never goes to the helper, which runs only the static
    side)."""
    if workers not in (1, 2):
        raise ValueError(f"workers must be 1 or 2, got {workers}")
    unknown = [s for s in video_seeds if s not in seeds]
    if unknown:
        raise ValueError(f"video seeds must be among the seeds, got {unknown}")
    start = time.perf_counter()
    here, helper = plan(seeds, video_seeds, film, size)
    if workers == 1:
        here, helper = here + helper, []
    pool, future = None, None
    if helper:
        ctx = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(max_workers=1, mp_context=ctx)
        future = pool.submit(_run_jobs, helper)
    try:
        t0 = time.perf_counter()
        planner = planner if planner is not None else fit_planner()
        fit_s = time.perf_counter() - t0
        done: list[DemoEpisode] = []
        for job in here:
            done += run_job(job, planner if job.side == "dynamic" else None, on_episode)
        if future is not None:
            for e in future.result():
                if on_episode is not None:
                    on_episode(e)
                done.append(e)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    order = {int(s): k for k, s in enumerate(seeds)}
    episodes = {side.key: sorted((e for e in done if e.side == side.key),
                                 key=lambda e: order[e.seed]) for side in SIDES}
    return DemoRun(episodes, fit_s, time.perf_counter() - start)


def _run_jobs(jobs: Sequence[DemoJob]) -> list[DemoEpisode]:
    """The helper process's jobs (a module-level function: spawned processes import it)."""
    return [e for job in jobs for e in run_job(job)]
