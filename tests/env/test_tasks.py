"""The handover variants are Task objects: receiver set-up, episode end and a weighted reward in
info; a task reads the env and returns values, it never writes an env attribute (dm_control's
Task)."""

from __future__ import annotations

import math
import pickle
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent
from agents.static import StaticAgent
from handover_env.envs.tasks import DynamicHandover, HandoverReward, HandoverTask, StaticHandover

DYNAMIC = "handover_env/DynamicHandover-v0"


def _episode(env, seed=0, agent=None):
    agent = agent or ReactiveAgent()
    obs, info = env.reset(seed=seed, options={"receiver": "id"})
    agent.reset()
    steps = []
    while True:
        obs, r, term, trunc, info = env.step(agent.act(obs))
        steps.append((r, info))
        if term or trunc:
            return steps


def test_each_env_has_its_task_with_the_default_weights():
    dyn, sta = gym.make(DYNAMIC).unwrapped, gym.make("handover_env/StaticHandover-v0").unwrapped
    assert type(dyn.task) is DynamicHandover and type(sta.task) is StaticHandover
    assert dyn.task.reward == sta.task.reward == HandoverReward(1.0, 2.0, 10.0, 10.0, 10.0)
    assert (
        sta.task.stabilisation_delay == 2.0
        and sta.task.handover_delay == 2.0
        and dyn.task.handover_delay == 0.0
    )
    assert dyn.task.enabled_time(dyn) == 0.0 and math.isinf(sta.task.enabled_time(sta))


def test_reward_terms_are_in_info_and_sum_to_the_reward():
    env = gym.make(DYNAMIC)
    steps = _episode(env)
    for r, info in steps:
        assert r == info["reward_time"] + info["reward_force"] + info["reward_outcome"]
        assert info["reward_time"] == pytest.approx(-1.0 / 30.0)
    assert steps[-1][1]["outcome"] == "success" and steps[-1][1]["reward_outcome"] == 10.0
    assert all(info["reward_outcome"] == 0.0 for _, info in steps[:-1])
    _, info = env.reset(seed=0)
    assert info["reward_time"] == info["reward_force"] == info["reward_outcome"] == 0.0


def test_reward_weights_are_constructor_arguments_and_leave_the_episode_alone():
    base = _episode(gym.make(DYNAMIC))
    weighted = _episode(gym.make(DYNAMIC, reward={"success": 3.0, "time_cost": 2.0}))
    assert (
        len(base) == len(weighted)
        and base[-1][1]["outcome"] == weighted[-1][1]["outcome"] == "success"
    )
    assert weighted[-1][1]["reward_outcome"] == 3.0
    assert weighted[0][0] == pytest.approx(2.0 * base[0][0])
    # a force threshold of 0 f_r makes every wrist force count
    forced = _episode(
        gym.make(DYNAMIC, task=DynamicHandover(reward=HandoverReward(force_threshold=0.0)))
    )
    assert min(info["reward_force"] for _, info in forced) < 0.0
    assert sum(info["reward_force"] for _, info in base) >= sum(
        info["reward_force"] for _, info in forced
    )


#: Every end of an episode but success (``handover_env.envs.base_handover.OUTCOMES``).
FAILURES = ("premature_release", "dropped", "unsafe_force", "missed", "unstable")


def test_reward_terms_are_the_documented_formula_with_exact_numbers():
    """``time = -time_cost dt``, ``force = -dt max(0, |F| - force_threshold f_r) / force_scale``,
    ``outcome = +success`` on success and ``-failure`` on any other end (HandoverReward)."""
    default = HandoverReward()
    dt, f_r = 1.0 / 30.0, 5.0
    # |F| = 25 N, 2 f_r = 10 N: 15 N of excess, costing 15 / 10 per second for 1/30 s
    assert default.terms(dt, 25.0, f_r, "running") == {
        "time": -1.0 / 30.0, "force": -(dt * 15.0 / 10.0), "outcome": 0.0}
    assert default.terms(dt, 25.0, f_r, "running")["force"] == pytest.approx(-0.05, abs=1e-15)
    # at or below the threshold the force costs nothing
    assert default.terms(dt, 10.0, f_r, "running")["force"] == 0.0
    assert default.terms(dt, 3.0, f_r, "running")["force"] == 0.0
    assert default.terms(dt, 0.0, f_r, "success") == {"time": -dt, "force": 0.0, "outcome": 10.0}
    for outcome in FAILURES:
        assert default.terms(dt, 0.0, f_r, outcome) == {
            "time": -dt, "force": 0.0, "outcome": -10.0}, outcome
    # every weight, and dt, enter as documented
    w = HandoverReward(time_cost=2.0, force_threshold=1.5, force_scale=4.0, success=3.0,
                       failure=7.0)
    for step in (0.005, 0.1):
        terms = w.terms(step, 20.0, 4.0, "missed")  # 20 - 1.5 * 4 = 14 N of excess
        assert terms["time"] == pytest.approx(-2.0 * step, rel=1e-15)
        assert terms["force"] == pytest.approx(-step * 14.0 / 4.0, rel=1e-15)
        assert terms["outcome"] == -7.0
    assert w.terms(0.1, 20.0, 4.0, "success")["outcome"] == 3.0
    assert w.terms(0.1, 20.0, 4.0, "running")["outcome"] == 0.0


class _HoldLowAndAway:
    """Holds the object low and away from the person's path: the person walks past it."""

    def reset(self):
        pass

    def act(self, obs):
        return np.array([-0.3, 0.1, 0.8, -math.pi / 2], dtype=np.float32)


@pytest.mark.parametrize("failure", [10.0, 7.0])
def test_a_missed_handover_costs_the_failure_penalty(failure):
    """A real physics episode that ends ``missed``: its last step pays ``-failure``."""
    env = gym.make(DYNAMIC, reward={"failure": failure})
    steps = _episode(env, agent=_HoldLowAndAway())
    r, info = steps[-1]
    assert info["outcome"] == "missed" and len(steps) < 600  # terminated, not truncated
    assert info["reward_outcome"] == -failure
    assert info["reward_time"] == pytest.approx(-1.0 / 30.0)
    assert r == info["reward_time"] + info["reward_force"] + info["reward_outcome"]
    assert r < -failure
    assert all(i["reward_outcome"] == 0.0 and i["outcome"] == "running" for _, i in steps[:-1])


def test_the_force_term_of_a_real_episode_is_the_formula():
    """Each step's ``reward_force`` is ``-dt max(0, |F| - threshold f_r) / force_scale`` of the
    wrist force the step ended with."""
    env = gym.make(DYNAMIC, task=DynamicHandover(reward=HandoverReward(force_threshold=0.0)))
    u = env.unwrapped
    agent = ReactiveAgent()
    obs, _ = env.reset(seed=0, options={"receiver": "id"})
    agent.reset()
    got, wanted = [], []
    while True:
        obs, _, term, trunc, info = env.step(agent.act(obs))
        got.append(info["reward_force"])
        wanted.append(-(u.dt * max(0.0, u.wrist_force_magnitude()) / 10.0))
        if term or trunc:
            break
    assert u.dt == pytest.approx(1.0 / 30.0)
    assert min(got) < -1e-3  # the held bottle's weight is felt
    np.testing.assert_array_equal(got, wanted)


@dataclass
class StandStill(HandoverTask):
    """A variant in a few lines: a person who never walks past (no 'missed'), nothing else
    changed."""

    def walked_past(self, env, t):
        return False


def test_a_new_variant_is_one_task_class():
    env = gym.make(DYNAMIC, task=StandStill(), max_episode_steps=40)
    assert isinstance(env.unwrapped.task, StandStill)
    steps = _episode(env, agent=_Still())
    assert steps[-1][1]["outcome"] == "running"  # truncated by the TimeLimit, never 'missed'
    clone = pickle.loads(pickle.dumps(env.unwrapped))
    assert isinstance(clone.task, StandStill)


class _Still:
    def reset(self):
        pass

    def act(self, obs):
        return np.array([0.3, -0.4, 1.15, -math.pi / 2], dtype=np.float32)


def test_bad_task_and_reward_arguments_are_clear_errors():
    with pytest.raises(ValueError, match="task must be a HandoverTask"):
        gym.make(DYNAMIC, task="static")
    with pytest.raises(ValueError, match="not both"):
        gym.make(DYNAMIC, task=DynamicHandover(), reward={"success": 1.0})
    with pytest.raises(ValueError, match="force_scale"):
        HandoverReward(force_scale=0.0)
    with pytest.raises(ValueError, match="finite"):
        HandoverReward(success=float("nan"))
    with pytest.raises(TypeError, match="unexpected keyword argument 'sucess'"):
        gym.make(DYNAMIC, reward={"sucess": 1.0})
    with pytest.raises(ValueError, match="stabilisation_delay"):
        StaticHandover(stabilisation_delay=-1.0)


# -------------------------------------------------------------- tasks write no env attribute
class _ReadOnlyEnv:
    """The env as a task sees it: every attribute readable, none writable."""

    def __init__(self, env) -> None:
        object.__setattr__(self, "_env", env)

    def __getattr__(self, name):
        return getattr(self._env, name)

    def __setattr__(self, name, value):
        raise AssertionError(f"a task wrote env.{name}")


class _Guarded:
    """A task whose methods get the read-only env."""

    def __init__(self, task) -> None:
        self._task = task

    def __getattr__(self, name):
        attr = getattr(self._task, name)
        if not callable(attr):
            return attr
        return lambda env, *args, **kwargs: attr(_ReadOnlyEnv(env), *args, **kwargs)


def _static_episode(guard: bool) -> tuple[list[float], dict, float, float]:
    env = gym.make("handover_env/StaticHandover-v0")
    u = env.unwrapped
    if guard:
        u.task = _Guarded(u.task)
    agent = StaticAgent()
    obs, _ = env.reset(seed=3, options={"receiver": "id"})
    agent.reset()
    enabled = [float(obs[u.layout.slices()["robot_enabled"][0]][0])]
    while True:
        obs, _, term, trunc, info = env.step(agent.act(obs))
        enabled.append(float(obs[u.layout.slices()["robot_enabled"][0]][0]))
        if term or trunc:
            break
    t_detect, t_enabled = u.t_detect, u.t_enabled
    env.close()
    return enabled, info, t_detect, t_enabled


def test_tasks_return_values_and_the_env_stores_them():
    enabled, info, t_detect, t_enabled = _static_episode(guard=True)
    # the env asked the task: the robot was held until the raised hand's detection + 2 s
    assert info["outcome"] == "success"
    assert not math.isnan(t_detect) and t_enabled == t_detect + 2.0
    assert enabled[0] == 0.0 and enabled[-1] == 1.0
    first = enabled.index(1.0)
    assert np.all(np.asarray(enabled[:first]) == 0.0) and np.all(np.asarray(enabled[first:]) == 1.0)
    assert abs(first / 30.0 - t_enabled) <= 1.0 / 30.0 + 1e-9
    # the same episode as with the task called directly
    plain = _static_episode(guard=False)
    assert plain[0] == enabled and plain[1] == info and plain[2:] == (t_detect, t_enabled)
