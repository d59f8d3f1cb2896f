"""Θ travels as one HandoverParams; the env reads its robot fields (K, B, f_r), an agent its t_f.

Checked in the code (no module of the env reads t_f, no agent or baseline reads K, B or f_r) and
in a rollout (the env's numbers do not move with t_f, an agent's actions do not move with K, B or
f_r). The env takes Θ as ``params=`` or, for ``gym.make`` users, as four loose keywords.
"""

from __future__ import annotations

import ast
from dataclasses import fields
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401  (registers the envs)
from agents.reactive import ReactiveAgent
from handover_env.config import AGENT_FIELDS, ROBOT_FIELDS, HandoverParams
from handover_env.envs import DynamicHandoverEnv
from handover_env.envs.config import EnvConfig

REPO = Path(__file__).resolve().parents[2]
ENV_ID = "handover_env/DynamicHandover-v0"


def _attributes_read(folder: str, names: tuple[str, ...], skip: tuple[str, ...] = ()) -> list:
    hits = []
    for path in sorted((REPO / folder).rglob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        if rel in skip:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and node.attr in names:
                hits.append(f"{rel}:{node.lineno} .{node.attr}")
    return hits


def test_the_split_covers_theta_once():
    assert sorted(ROBOT_FIELDS + AGENT_FIELDS) == sorted(f.name for f in fields(HandoverParams))
    assert not set(ROBOT_FIELDS) & set(AGENT_FIELDS)


def test_no_env_module_reads_an_agent_field():
    hits = _attributes_read("handover_env", AGENT_FIELDS, skip=("handover_env/config.py",))
    assert hits == [], hits


@pytest.mark.parametrize("folder", ["agents", "baselines"])
def test_no_agent_reads_a_robot_field(folder):
    assert _attributes_read(folder, ROBOT_FIELDS) == []


def _rollout(env: gym.Env, agent: ReactiveAgent, steps: int = 45) -> tuple[list, list]:
    obs, _ = env.reset(seed=4, options={"receiver": "id"})
    agent.reset()
    observations, actions = [obs], []
    for _ in range(steps):
        action = agent.act(obs)
        obs, _, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        actions.append(action)
        if terminated or truncated:
            break
    return observations, actions


def test_the_env_does_not_move_with_t_f_nor_the_agent_with_k_b_f_r():
    agent = ReactiveAgent(HandoverParams())
    base_obs, base_act = _rollout(gym.make(ENV_ID, sensing="ideal"), agent)
    other_tf = gym.make(ENV_ID, sensing="ideal", params=HandoverParams(forecast_time=0.9))
    obs, act = _rollout(other_tf, agent)
    assert all(np.array_equal(a, b) for a, b in zip(obs, base_obs, strict=True))
    assert all(np.array_equal(a, b) for a, b in zip(act, base_act, strict=True))
    robot_only = HandoverParams(stiffness=80.0, damping=10.0, release_force=20.0)
    other = ReactiveAgent(robot_only)
    assert all(
        np.array_equal(other.act(o), a) for o, a in zip(base_obs[:-1], base_act, strict=True)
    )


def test_params_and_the_loose_keywords_build_the_same_env():
    theta = HandoverParams(stiffness=100.0, damping=12.0, forecast_time=0.3, release_force=9.0)
    by_params = gym.make(ENV_ID, params=theta).unwrapped
    by_dict = gym.make(ENV_ID, params={"stiffness": 100.0, "damping": 12.0,
                                       "forecast_time": 0.3, "release_force": 9.0}).unwrapped
    loose = gym.make(ENV_ID, stiffness=100.0, damping=12.0, forecast_time=0.3,
                     release_force=9.0).unwrapped
    by_config = DynamicHandoverEnv(config=EnvConfig(params=theta))
    for env in (by_dict, loose, by_config):
        assert env.params == theta and env.config == by_params.config
    assert by_params.controller.params == loose.controller.params == theta


def test_theta_given_twice_or_a_stray_keyword_is_one_clear_error():
    with pytest.raises(ValueError, match=r"params= or as \['damping'\].*not both"):
        gym.make(ENV_ID, params=HandoverParams(), damping=3.0)
    with pytest.raises(TypeError, match=r"unknown env argument\(s\) \['stifness'\]"):
        gym.make(ENV_ID, stifness=100.0)
    with pytest.raises(ValueError, match="params must be a HandoverParams"):
        gym.make(ENV_ID, params=(100.0, 12.0, 0.3, 9.0))
    with pytest.raises(ValueError, match="config= or as keywords"):
        DynamicHandoverEnv(config=EnvConfig(), sensing="ideal")
    with pytest.raises(ValueError, match="release_force must be > 0"):
        EnvConfig(params={"release_force": 0.0})
