"""An agent's two roles: a Predictor (fit, predict*) and a Policy (reset, act); Agent is both."""

from __future__ import annotations

import ast
import inspect

import numpy as np
import pytest

import agents.base as base
from agents.base import Agent, Policy, Predictor
from agents.null import NullAgent
from agents.reactive import ReactiveAgent
from agents.static import StaticAgent

READY = np.array([0.3, -0.4, 1.15, -np.pi / 2], dtype=np.float32)


class HoldStill(Policy):
    """A policy alone: it acts, and has nothing to predict."""

    def reset(self) -> None:
        self.steps = 0

    def act(self, obs: np.ndarray) -> np.ndarray:
        self.steps += 1
        return READY.copy()


class LastPoint(Predictor):
    """A predictor alone: the last receiver position, held, at 1.2 m."""

    horizon = 5

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        hist = base.validate_history(receiver_history)
        return np.tile([*hist[-1], 1.2], (self.horizon, 1))


def test_a_policy_needs_no_predict_and_a_predictor_no_act():
    policy = HoldStill()
    policy.reset()
    assert np.array_equal(policy.act(np.zeros(90)), READY) and policy.steps == 1
    assert not hasattr(policy, "predict") and not isinstance(policy, (Predictor, Agent))
    predictor = LastPoint().fit([])
    out = predictor.predict_sequence(np.array([[0.0, 1.0], [2.0, 3.0]]), np.array([0, 1]))
    assert out.shape == (2, 5, 3) and out[1, 0].tolist() == [2.0, 3.0, 1.2]
    assert not hasattr(predictor, "act") and not isinstance(predictor, (Policy, Agent))


def test_each_role_requires_its_own_methods():
    class NoAct(Policy):
        def reset(self) -> None:
            pass

    class NoPredict(Agent):
        def reset(self) -> None:
            pass

        def act(self, obs: np.ndarray) -> np.ndarray:
            return READY

    for cls, missing in ((NoAct, "act"), (NoPredict, "predict"), (Predictor, "predict")):
        with pytest.raises(TypeError, match=f"abstract method.*{missing}"):
            cls()


def test_the_built_in_agents_play_both_roles():
    for agent in (ReactiveAgent(), StaticAgent(), NullAgent()):
        assert isinstance(agent, Predictor) and isinstance(agent, Policy)


def test_no_method_of_the_roles_is_a_not_implemented_stub():
    tree = ast.parse(inspect.getsource(base))
    raised = [
        node.exc for node in ast.walk(tree) if isinstance(node, ast.Raise) and node.exc is not None
    ]
    names = [ast.unparse(exc) for exc in raised]
    assert names and not any("NotImplementedError" in name for name in names)
