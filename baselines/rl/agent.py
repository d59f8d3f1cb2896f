"""The RL policy as a :class:`~agents.base.Policy`: what ``evaluate.py closed-loop --agents
rl-residual rl-scratch`` runs.

:class:`RLAgent` holds a policy rebuilt from a checkpoint
(:func:`baselines.rl.files.read_checkpoint`, nothing unpickled) or the live policy of a training
run, the fixed observation / action mapping (:class:`baselines.rl.envs.PolicyIO`) and, for the
residual form, its base agent. ``act(obs)`` is the same computation as one step of the training
wrapper (the action filter and the memory of the last actions included), with the policy's
deterministic action (its mean). The agent acts in the env only: it
has no open-loop prediction.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from agents.base import Agent, Policy
from baselines.checkpoint_io import CheckpointError
from baselines.rl.config import TRAIN_SEED_START, RLConfig
from baselines.rl.envs import PolicyIO
from baselines.rl.layout import PRIVILEGED_SIZE
from handover_env.config import HandoverParams


def make_base(config: RLConfig, params: HandoverParams | None = None, fit_data: Any = None):
    """The residual's base agent: the reactive agent (Θ's t_f), the constant-velocity agent
    (``cv``: the reactive agent's extrapolation in the predictive wrapper, Θ's t_f), or the SPGP
    planner (``ours``) fitted on ``fit_data`` (the training folds' episodes); None for
    scratch."""
    if config.form != "residual":
        return None
    return build_agent(config.base, params, fit_data)


def build_agent(name: str, params: HandoverParams | None = None, fit_data: Any = None):
    """The agent ``name`` (``"reactive"``, ``"cv"`` or ``"ours"``) as a residual's base or a
    warm start's teacher (:func:`make_base`)."""
    if name == "reactive":
        from agents.reactive import ReactiveAgent

        return ReactiveAgent(params or HandoverParams())
    if name == "cv":
        from agents.constant_velocity import ConstantVelocityAgent

        return ConstantVelocityAgent(params=params or HandoverParams())
    if fit_data is None or len(fit_data) == 0:
        raise ValueError("'ours' (a residual's base or a warm start's teacher) needs the training "
                         "folds' episodes to fit the SPGP planner (--data)")
    from agents.nonparametric import NonparametricAgent, NonparametricConfig

    base = NonparametricAgent(NonparametricConfig()).fit(fit_data)
    if params is not None:
        base.params = params  # type: ignore[attr-defined]
    return base


class RLAgent(Policy):
    """A trained SB3 policy acting in the handover env (module docstring).

    Args:
        policy: the SB3 policy (weights loaded).
        io: its observation normalisation and action mapping.
        base: the residual's base agent (None for scratch).
        trained_replays: source ids of the recordings the policy trained on (refused as test
            receivers by :meth:`check_receiver`).
        record: the checkpoint's JSON record (empty for a live policy).
    """

    def __init__(self, policy: Any, io: PolicyIO, base: Agent | None = None,
                 trained_replays: frozenset[str] = frozenset(), record: dict | None = None) -> None:
        if (io.config.form == "residual") != (base is not None):
            raise ValueError("a residual RL agent needs its base agent (and a scratch one none)")
        self.policy, self.io, self.base = policy, io, base
        self.config = io.config
        self.memory = io.memory()
        self.trained_replays = frozenset(trained_replays)
        self.record = record or {}

    @classmethod
    def load(cls, folder: str | Path, params: HandoverParams | None = None,
             fit_data: Any = None) -> RLAgent:
        """The agent of the checkpoint in ``folder`` (read-only, nothing unpickled).

        Args:
            params: Θ; its t_f goes to a reactive base agent.
            fit_data: for a residual on ``ours``: the episodes its SPGP base was fitted on (their
                source ids are checked against the checkpoint's record).
        """
        from baselines.rl.files import read_checkpoint

        ckpt = read_checkpoint(folder)
        want = ckpt.record["receivers"].get("base_fit_ids", [])
        if ckpt.config.form == "residual" and ckpt.config.base == "ours":
            got = sorted(ep.source_id for ep in fit_data) if fit_data is not None else []
            if got != sorted(want):
                raise CheckpointError(
                    f"{folder}: its SPGP base was fitted on {len(want)} recordings of the "
                    "training folds; pass exactly those episodes (the same dataset) to load it")
        base = make_base(ckpt.config, params, fit_data)
        return cls(ckpt.policy, ckpt.io, base, frozenset(ckpt.record["receivers"]["replay_ids"]),
                   ckpt.record)

    @property
    def params(self) -> HandoverParams | None:
        return getattr(self.base, "params", None)

    @params.setter
    def params(self, value: HandoverParams) -> None:
        if self.base is not None:
            self.base.params = value  # type: ignore[attr-defined]

    def check_receiver(self, kind: str, key: str, seed: int) -> None:
        """Refuse (ValueError) a test receiver the policy trained on: a replay of a recording in
        its training folds, or a walker seed of a range its checkpoint records
        (:meth:`trained_seed_ranges`; the benchmark's test seeds, 2e8 and up, lie outside them)."""
        if kind == "replay" and key in self.trained_replays:
            raise ValueError(
                f"the RL policy trained on the recording {key!r}; score it on held-out folds only "
                "(evaluate.py closed-loop --replay-folds of the held-out half)")
        if kind == "replay":
            return
        ranges = self.trained_seed_ranges()
        if ranges is None and seed >= TRAIN_SEED_START:
            raise ValueError(f"walker seed {seed} is in the RL training range (>= "
                             f"{TRAIN_SEED_START}); evaluation seeds lie below it")
        for low, high in ranges or ():
            if low <= seed <= high:
                raise ValueError(f"walker seed {seed} is in the RL training range: the policy "
                                 f"trained on the walkers of seeds {low}..{high}")

    def trained_seed_ranges(self) -> list[tuple[int, int]] | None:
        """The walker seeds the checkpoint records it met (its learning-curve, episode and
        warm-start ranges, each taken whole); None for a policy with no record, for which every
        seed from :data:`TRAIN_SEED_START` on counts as trained on."""
        from baselines.rl.files import SEED_RANGE_KEYS

        receivers = self.record.get("receivers")
        if not receivers:
            return None
        ranges = (receivers.get(key, []) for key in SEED_RANGE_KEYS)
        return [(min(r), max(r)) for r in ranges if r]  # read_record: [] or two whole seeds

    def reset(self) -> None:
        self.memory.reset()
        if self.base is not None:
            self.base.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        base_target = None
        if self.base is not None:
            base_target = np.asarray(self.base.act(obs), dtype=np.float64)
        x: Any = self.io.observation(obs, base_target, self.memory.observation())
        if self.config.privileged_critic:  # the critic's part: never read by the actor
            x = {"actor": x, "privileged": np.zeros(PRIVILEGED_SIZE, np.float32)}
        with torch.no_grad():
            action, _ = self.policy.predict(x, deterministic=True)
        return self.io.target(self.memory.apply(action), base_target)
