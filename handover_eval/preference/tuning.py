"""CoSpar on the env: simulated participants judge real handovers and CoSpar learns Theta from them.

The paper's fine-tuning phase (Sec. IV-B, V-B-1): CoSpar (Tucker et al. 2020) over 20 iterations,
K in [80, 140], B in [10, 20], t_f in [0, 1] s, f_r in [5, 20] N. Here every iteration:

1. CoSpar draws ``n_samples`` utility functions from its Laplace posterior (paper Eqs. 2-3) and
   proposes their argmax actions (Thompson sampling, :mod:`agents.cospar`);
2. each proposed Theta is run as real episodes in the env (:func:`handover_eval.episodes.play`
   in this process's env of that Theta, :func:`handover_eval.episodes.env_for`): the planner
   (``ours``: the SPGP planner fitted once on the synthetic default, which uses t_f; K, B and f_r
   are the env's) hands the bottle to scripted walkers with the participant's body and path, one
   episode per walk, the same ``walks`` walker seeds for every Theta (common random numbers;
   :class:`EpisodeRunner` caches episodes by participant, walk and Theta);
3. the participant (:mod:`agents.participants`) compares every pair among the new actions and the
   ``buffer_size`` actions they tried last, by their mean satisfaction over the walks, with the
   probit noise of Eq. 2; each answer is a preference added to the data (episodes the env ended
   as ``unstable``, a numerical event, are not judged: :func:`lived`);
4. the posterior is updated.

Theta-hat is the argmax of the posterior mean over the actions tried (``CoSpar.best``); the
argmax over the whole grid is reported beside it. With several participants (``--participants
8``) they share one posterior, as the paper learned one Theta-hat from its volunteers: in each
iteration every participant in turn makes one such step (their own buffer, their own walks), so
an iteration holds ``participants x n_samples`` new actions.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.cospar import THETA_NAMES, CoSpar, CoSparConfig
from agents.participants import COST_NAMES, Participant
from handover_env.config import HandoverParams
from handover_eval import roster
from handover_eval.episodes import clear_envs, env_for, play
from handover_eval.methods import MethodOptions

#: The paper's learned Theta-hat (Sec. V-B-1), printed beside ours; never given to participants.
PAPER_THETA = (114.3, 17.1, 0.14, 7.1)
#: The roster's agents CoSpar tunes Θ for.
AGENTS = ("ours", "reactive")
RECEIVERS = ("id", "ood", "replay")
#: ``info`` keys kept per episode (numbers or the outcome string).
INFO_KEYS = (
    "outcome",
    "handover_time",
    "handover_time_with_delay",
    "transfer_time",
    "release_time",
    "release_force",
    "pull_force",
    "peak_wrist_force",
    "body_contact_force",
    "penetration",
    "reach_distance",
    "arm_extended_time",
    "time_lost",
    "min_speed_factor",
    "path_deviation",
    "robot_jerk_rms",
    "robot_jerk_peak",
)
CONTACT_PREFIX = "contact_force_"
OUTCOME_COLUMNS = ("success_rate", "handover_time", "pull_force", "release_force", "reach_distance",
                   "body_contact_force", "robot_jerk_rms", "time_lost")
#: Measured outcomes whose names clash with Theta's are renamed in summaries.
_RENAMED = {"release_force": "measured_release_force"}


def _keep(info: Mapping) -> dict[str, Any]:
    """The episode facts a participant may judge (JSON-friendly)."""
    out: dict[str, Any] = {}
    for k, v in info.items():
        if k in INFO_KEYS or k.startswith(CONTACT_PREFIX):
            out[k] = v if (v is None or isinstance(v, str)) else float(v)
    if info.get("TimeLimit.truncated") or (out.get("outcome") == "running"):
        out["outcome"] = "timeout"
    return out


class EpisodeRunner:
    """Runs one agent with a given Theta on a participant's walks, in the dynamic or static env
    (this process's env of that Theta, :func:`handover_eval.episodes.env_for`).

    Args:
        agent: ``"ours"`` (SPGP planner fitted on ``dataset``, or on the synthetic default) or
            ``"reactive"`` (built by :mod:`handover_eval.roster`).
        receiver: ``"id"``/``"ood"`` scripted walkers with the participant's body, or ``"replay"``
            (synthetic demonstrations closest to the participant's speed, at their height).
        dataset: training data of ``ours`` and the replay pool (default: ``load_any(None)``).
        sensing: the env's sensing profile (``"paper"``, the env's default, ``"ideal"`` or
            ``"randomized"``; docs/sensing.md).
    """

    def __init__(self, agent: str = "ours", receiver: str = "id", dataset: Any = None,
                 sensing: str = "paper") -> None:
        from handover_env.sensors.profiles import PROFILES

        if agent not in AGENTS:
            raise ValueError(f"agent must be one of {AGENTS}, got {agent!r}")
        if receiver not in RECEIVERS:
            raise ValueError(f"receiver must be one of {RECEIVERS}, got {receiver!r}")
        if sensing not in PROFILES:
            raise ValueError(f"sensing must be one of {list(PROFILES)}, got {sensing!r}")
        self.agent_name, self.receiver, self.sensing = agent, receiver, sensing
        self._dataset = dataset
        self._agent: Any = None
        self._static_agent: Any = None
        self._speeds: np.ndarray | None = None
        self.cache: dict[tuple, dict[str, Any]] = {}
        self.episodes_run = 0
        self.seconds = 0.0

    # ------------------------------------------------------------------ lazy pieces
    def dataset(self) -> Any:
        if self._dataset is None:
            from handover_env.person.demos import load_any

            self._dataset = load_any(None)
        return self._dataset

    def planner(self, theta: HandoverParams) -> Any:
        """The planning agent (``ours`` or ``reactive``) fitted once, with ``theta`` set."""
        if self._agent is None:
            agent = roster.build(self.agent_name, MethodOptions(workers=1))
            if roster.entry(self.agent_name).learns:
                agent = agent.fit(self.dataset())  # type: ignore[attr-defined]
            self._agent = agent
        self._agent.params = theta
        return self._agent

    def env(self, theta: HandoverParams, static: bool = False) -> Any:
        """This process's env (static or dynamic) of ``theta`` on the runner's sensing."""
        return env_for("static" if static else "dynamic", theta,
                       json.dumps({"sensing": self.sensing}))

    def _options(self, participant: Participant, seed: int) -> dict:
        if self.receiver != "replay":
            return participant.walk_options(self.receiver)
        data = self.dataset()
        if self._speeds is None:
            self._speeds = np.array(
                [
                    float(np.median(np.linalg.norm(np.diff(ep.receiver_xy, axis=0), axis=1)))
                    * data.rate_hz
                    for ep in data
                ]
            )
        order = np.argsort(np.abs(self._speeds - participant.body.speed), kind="stable")
        episode = data[int(order[seed % min(len(order), 50)])]
        return {"receiver": "replay", "episode": episode, "height": participant.body.height}

    # ------------------------------------------------------------------ running
    def cache_key(
        self, participant: Participant, theta: HandoverParams, seed: int, static: bool = False
    ) -> tuple:
        """The episode cache's key of one walk of ``participant`` with ``theta``."""
        return (
            participant.pid,
            participant.seed,
            self.receiver,
            self.agent_name,
            static,
            int(seed),
            tuple(round(v, 9) for v in theta.as_array()),
        )

    def run(self, participant: Participant, theta: HandoverParams, seeds: Sequence[int],
            static: bool = False) -> list[dict[str, Any]]:
        """One episode per walk seed (cached); the static env uses the static agent."""
        import time

        out = []
        for seed in seeds:
            key = self.cache_key(participant, theta, seed, static)
            if key not in self.cache:
                t0 = time.perf_counter()
                env = self.env(theta, static)
                if static:
                    if self._static_agent is None:
                        self._static_agent = roster.build("static", MethodOptions(workers=1))
                    agent = self._static_agent
                else:
                    agent = self.planner(theta)
                played = play(env, agent, int(seed), self._options(participant, int(seed)))
                self.cache[key] = _keep(played.info)
                self.episodes_run += 1
                self.seconds += time.perf_counter() - t0
            out.append(self.cache[key])
        return out

    def close(self) -> None:
        """Close this process's envs (:func:`handover_eval.episodes.clear_envs`; the runner holds
        none itself, so it pickles, to a sweep's workers, with its fitted planner and episode
        cache only)."""
        clear_envs()


def lived(infos: Sequence[Mapping]) -> list[Mapping]:
    """The episodes a participant judges: all but those the env ended as ``unstable`` (MuJoCo reset
    a diverging simulation: a numerical event no person lives through). If every episode is
    unstable, all are returned (and judged as failed handovers)."""
    kept = [i for i in infos if i.get("outcome") != "unstable"]
    return kept or list(infos)


def summarise_outcomes(infos: Sequence[Mapping]) -> dict[str, float]:
    """Mean outcome measures over episodes (times over successful ones; NaN if none); the measured
    release force is ``measured_release_force`` (``release_force`` is Theta's f_r)."""
    ok = [i for i in infos if i.get("outcome") == "success"]

    def mean(key: str, rows: Sequence[Mapping]) -> float:
        vals = [float(r[key]) for r in rows if r.get(key) is not None]
        return float(np.mean(vals)) if vals else math.nan

    out = {
        "success_rate": len(ok) / len(infos) if infos else math.nan,
        "handover_time": mean("handover_time", ok),
        "unstable": float(sum(i.get("outcome") == "unstable" for i in infos)),
    }
    for key in OUTCOME_COLUMNS[2:]:
        out[_RENAMED.get(key, key)] = mean(key, infos)
    return out


@dataclass(frozen=True)
class PreferenceConfig:
    """Settings of a CoSpar run on the env.

    Args:
        iterations: CoSpar iterations (the paper: 20).
        walks: walks (episodes) per proposed Theta and participant.
        agent: ``"ours"`` or ``"reactive"``.
        receiver: ``"id"``, ``"ood"`` or ``"replay"``.
        sensing: the env's sensing profile (see :class:`EpisodeRunner`).
        cospar: the learner's settings (grid over the paper's ranges, kernel, noise, Thompson
            samples, buffer).
        seed: seeds the Thompson samples.
        walk_stream: which of the participant's walk-seed streams to tune on.
    """

    iterations: int = 20
    walks: int = 3
    agent: str = "ours"
    receiver: str = "id"
    sensing: str = "paper"
    cospar: CoSparConfig = field(default_factory=CoSparConfig)
    seed: int = 0
    walk_stream: int = 0

    def __post_init__(self) -> None:
        if self.iterations < 1 or self.walks < 1:
            raise ValueError(
                f"need iterations >= 1 and walks >= 1, got {self.iterations}, {self.walks}"
            )
        if self.agent not in AGENTS or self.receiver not in RECEIVERS:
            raise ValueError(f"agent must be one of {AGENTS} and receiver one of {RECEIVERS}")


@dataclass
class PreferenceResult:
    """Theta-hat, the learner and the history of a CoSpar run."""

    theta_hat: HandoverParams
    theta_hat_grid: HandoverParams
    learner: CoSpar
    history: list[dict[str, Any]]
    preferences: list[dict[str, Any]]
    episodes: int
    episode_seconds: float
    seconds: float


def run_preference(participants: Sequence[Participant], config: PreferenceConfig,
                   runner: EpisodeRunner | None = None, progress: bool = False,
                   judge: Callable[[Participant, int], float] | None = None) -> PreferenceResult:
    """CoSpar with ``participants`` sharing one posterior (one participant: the paper's protocol).

    Args:
        participants: who answers (each keeps their own buffer of recently tried actions).
        config: :class:`PreferenceConfig`.
        runner: runs the episodes (a new :class:`EpisodeRunner` by default).
        progress: tqdm bar over iterations.
        judge: optional ``(participant, action index) -> utility`` replacing the env (tests, and
            the brute-force check, which reads cached episodes through it).

    Returns:
        :class:`PreferenceResult`.
    """
    import time

    from handover_eval.preference.batch import prefetch

    if not participants:
        raise ValueError("need at least one participant")
    start = time.perf_counter()
    runner = runner or EpisodeRunner(config.agent, config.receiver, sensing=config.sensing)
    learner = CoSpar(config.cospar, seed=config.seed)
    grid = learner.grid
    buffers: dict[int, list[int]] = {p.pid: [] for p in participants}
    seeds = {p.pid: p.walk_seeds(config.walks, config.walk_stream) for p in participants}
    memory: dict[tuple[int, int], tuple[float, dict[str, float]]] = {}
    history: list[dict[str, Any]] = []
    prefs: list[dict[str, Any]] = []

    def experience(p: Participant, a: int) -> tuple[float, dict[str, float]]:
        if (p.pid, a) not in memory:
            if judge is not None:
                memory[(p.pid, a)] = (float(judge(p, a)), {})
            else:
                infos = lived(runner.run(p, HandoverParams(*grid[a]), seeds[p.pid]))
                costs = {
                    f"cost_{c}": float(np.mean([p.costs(i)[c] for i in infos])) for c in COST_NAMES
                }
                memory[(p.pid, a)] = (p.utility(infos), {**summarise_outcomes(infos), **costs})
        return memory[(p.pid, a)]

    steps = range(config.iterations)
    if progress:
        from tqdm import tqdm

        steps = tqdm(
            steps,
            desc=f"CoSpar ({len(participants)} participant{'s' * (len(participants) > 1)})",
            unit="iter",
        )
    for it in steps:
        for p in participants:
            tried = learner.propose()
            if judge is None:  # the new actions' walks as parallel tasks on a Ray backend
                prefetch(
                    runner,
                    p,
                    [HandoverParams(*grid[a]) for a in tried if (p.pid, a) not in memory],
                    seeds[p.pid],
                )
            buffer = (
                buffers[p.pid][-config.cospar.buffer_size :] if config.cospar.buffer_size else []
            )
            compared = list(dict.fromkeys(tried + buffer))
            wins = dict.fromkeys(compared, 0)
            for i in range(len(compared)):
                for j in range(i + 1, len(compared)):
                    a, b = compared[i], compared[j]
                    ua, ub = experience(p, a)[0], experience(p, b)[0]
                    winner, loser = (a, b) if p.prefers(ua, ub) else (b, a)
                    learner.add_preference(winner, loser)
                    wins[winner] += 1
                    prefs.append(
                        {
                            "iteration": it,
                            "participant": p.pid,
                            **{f"winner_{n}": grid[winner][k] for k, n in enumerate(THETA_NAMES)},
                            **{f"loser_{n}": grid[loser][k] for k, n in enumerate(THETA_NAMES)},
                            "winner_index": winner,
                            "loser_index": loser,
                        }
                    )
            for a in compared:
                utility, outcomes = experience(p, a)
                history.append(
                    {
                        "iteration": it,
                        "participant": p.pid,
                        "role": "new" if a in tried else "buffer",
                        "action": a,
                        **{n: grid[a][k] for k, n in enumerate(THETA_NAMES)},
                        "comparisons_won": wins[a],
                        "comparisons": len(compared) - 1,
                        "hidden_utility": utility,
                        **outcomes,
                    }
                )
            buffers[p.pid].extend(tried)
            learner.history.extend(tried)
            learner.update_posterior()
    return PreferenceResult(
        theta_hat=learner.best(),
        theta_hat_grid=learner.best(tried_only=False),
        learner=learner,
        history=history,
        preferences=prefs,
        episodes=runner.episodes_run,
        episode_seconds=runner.seconds,
        seconds=time.perf_counter() - start,
    )
