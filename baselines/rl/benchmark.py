"""A trained RL checkpoint as a benchmark plug-in, scored on the closed-loop track.

    python evaluate.py benchmark --agent baselines.rl.benchmark:rl_agent \\
        --agent-config '{"checkpoint": "runs/rl"}' --tracks closedloop --name rl-residual

``rl_agent(checkpoint)`` loads the checkpoint through the safe loader
(:meth:`baselines.rl.agent.RLAgent.load`: nothing unpickled, every field and tensor checked) and
wraps it as an :class:`agents.base.Agent`, the type a plug-in returns. The policy acts; it has no
open-loop prediction, so the run is ``--tracks closedloop`` (``predict`` names the flag).
``fit`` learns nothing: the policy was trained by ``train.py rl``.

**What it may meet.** The benchmark's closed-loop replays are folds 5..9 of the 10-fold split of
seed 0 (``handover_eval.benchmark.protocol``), the held-out half; a policy trained on replays is
accepted only if they came from folds 0..4 of that same split (``folds`` 10, ``split_seed`` 0),
so the two are disjoint by construction, or if it trained on walkers only (``p_replay`` 0). Its
walkers are test seeds, below every training seed. With ``--replay-data``, the replays are
recordings outside ``--data``: that the policy never trained on them is the user's to keep
(``config.json`` lists the recordings it did). A residual on ``ours`` needs the episodes its SPGP
base was fitted on and is refused here; use ``evaluate.py closed-loop --rl-checkpoint``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Agent
from baselines.rl.agent import RLAgent
from handover_env.config import HandoverParams

#: The benchmark's replay split (handover_eval.benchmark.protocol: REPLAY_FOLDS, REPLAY_SEED).
BENCHMARK_SPLIT = (10, 0)


class RLBenchmarkAgent(Agent):
    """An :class:`RLAgent` as a closed-loop-only benchmark agent (module docstring)."""

    horizon = 30

    def __init__(self, agent: RLAgent) -> None:
        self.agent = agent
        self.config = agent.config

    @property
    def params(self) -> HandoverParams | None:
        return self.agent.params

    @params.setter
    def params(self, value: HandoverParams) -> None:
        self.agent.params = value

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        raise ValueError("an RL policy acts in the env and has no open-loop prediction: score it "
                         "with evaluate.py benchmark --tracks closedloop")

    def reset(self) -> None:
        self.agent.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.agent.act(obs)

    def check_receiver(self, kind: str, key: str, seed: int) -> None:
        """Refuse a receiver the policy trained on (:meth:`RLAgent.check_receiver`)."""
        self.agent.check_receiver(kind, key, seed)


def rl_agent(checkpoint: str, **unused: Any) -> RLBenchmarkAgent:
    """The benchmark plug-in of the RL checkpoint folder ``checkpoint`` (module docstring)."""
    if unused:
        raise ValueError(f"rl_agent takes only checkpoint, got {sorted(unused)}")
    agent = RLAgent.load(checkpoint, params=HandoverParams())
    c = agent.config
    if c.form == "residual" and c.base == "ours":
        raise ValueError(f"{checkpoint}: a residual on 'ours' needs its SPGP base's episodes; "
                         "score it with evaluate.py closed-loop --rl-checkpoint")
    if c.p_replay > 0 and (c.folds, c.split_seed) != BENCHMARK_SPLIT:
        raise ValueError(
            f"{checkpoint}: trained on replays of folds 0..{c.folds // 2 - 1} of a {c.folds}-fold "
            f"split of seed {c.split_seed}; the benchmark replays folds 5..9 of the 10-fold split "
            "of seed 0, which only a policy trained with --folds 10 --split-seed 0 never met")
    return RLBenchmarkAgent(agent)
