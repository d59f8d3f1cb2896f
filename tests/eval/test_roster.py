"""The one table of agents (handover_eval.roster) and the one closed-loop episode runner
(handover_eval.episodes): what every command reads, the spellings the result files print, one
entry adds an agent everywhere, and the Θ-keyed envs."""

from __future__ import annotations

import dataclasses
import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import pytest

from agents.base import Agent, Policy
from handover_env.config import HandoverParams
from handover_eval import episodes, roster
from handover_eval.benchmark import plugin
from handover_eval.methods import METHODS, MethodOptions, check_methods
from handover_eval.receivers import ReceiverSpec
from handover_eval.reporting import PAPER_TABLE1


def test_the_result_files_spellings_and_labels_are_those_they_have_always_printed() -> None:
    # Table I's rows and order, the closed-loop agents and order, the benchmark's built-ins
    assert METHODS == ("ours", "iaal", "act", "bc_mlp", "cv")
    assert roster.compared_agents() == (
        "reactive", "static", "ours", "iaal", "bc-mlp", "act", "giver-replay", "null", "lagging",
        "rl-residual", "rl-scratch")
    assert roster.benchmark_agents() == (
        "ours", "iaal", "act", "bc_mlp", "cv", "reactive", "null", "lagging", "rl")
    assert set(PAPER_TABLE1) <= set(METHODS)
    labels = {n: roster.label(n) for n in roster.names()}
    assert labels == {
        "reactive": "Reactive", "static": "Static (Meng et al.)", "ours": "Ours (SPGP)",
        "iaal": "IAAL", "bc_mlp": "BC-MLP", "act": "ACT", "cv": "Constant velocity",
        "giver-replay": "Giver replay (ref.)", "null": "Null (holds still)",
        "lagging": "Lagging (reactive +0.5 s)", "rl": "RL residual on cv (shipped)",
        "rl-residual": "RL residual",
        "rl-scratch": "RL from scratch"}
    assert roster.label("bc-mlp") == "BC-MLP" and roster.label("all") == "all"


def test_every_spelling_names_one_entry_and_each_command_takes_its_own() -> None:
    assert roster.entry("bc-mlp") is roster.entry("bc_mlp")
    assert roster.entry("giver_replay").name == "giver-replay"
    assert check_methods(["bc-mlp", "ours", "bc_mlp"]) == ["bc_mlp", "ours"]
    assert roster.check_agents(["bc_mlp", "giver_replay"]) == ["bc-mlp", "giver-replay"]
    assert plugin.resolve("bc-mlp").name == "bc_mlp" and plugin.resolve("null").kind == "roster"
    assert roster.env_kind("static") == "static" and roster.env_kind("bc-mlp") == "dynamic"
    with pytest.raises(ValueError, match=r"unknown agent\(s\) \['cv-fast'\]"):
        roster.check_agents(["cv-fast"])
    with pytest.raises(ValueError, match=r"unknown method\(s\) \['reactive'\]"):
        check_methods(["reactive"])  # a closed-loop-only agent predicts nothing
    with pytest.raises(ValueError, match="not a built-in"):
        plugin.resolve("giver-replay")  # replays only: not on the benchmark's walkers
    bad = (*roster.ROSTER, roster.AgentEntry("cv2", "CV 2", roster.ROSTER[0].build,
                                             aliases=("cv",)))
    with pytest.MonkeyPatch.context() as mp, pytest.raises(
            ValueError, match="two roster entries answer to 'cv'"):
        mp.setattr(roster, "ROSTER", bad)
        roster.find("ours")


def test_a_malformed_entry_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="x: tracks must be among"):
        roster.AgentEntry("x", "X", roster.ROSTER[0].build, tracks=("sideways",))
    with pytest.raises(ValueError, match="x: env must be one of"):
        roster.AgentEntry("x", "X", roster.ROSTER[0].build, env="moving")
    with pytest.raises(ValueError, match="x: an RL policy"):
        roster.AgentEntry("x", "X", None)


def test_every_builder_builds_its_role_and_make_agent_sets_theta() -> None:
    options = MethodOptions(quick=True, workers=1)
    theta = HandoverParams(forecast_time=0.5)
    for e in roster.ROSTER:
        if e.build is None:
            with pytest.raises(ValueError, match="is an RL policy"):
                roster.build(e.name, options)
            continue
        agent = roster.build(e.name, options, theta)
        assert isinstance(agent, Policy), e.name
        if "openloop" in e.tracks:
            assert isinstance(agent, Agent), e.name
    assert roster.make_agent("reactive", theta, options).params == theta
    assert roster.build("ours", options, inducing_ratio=0.2).config.inducing_ratio == 0.2
    with pytest.raises(ValueError, match="ours needs its fold model"):
        roster.make_agent("ours", theta, options)


def _cv_slow(options: MethodOptions, params: HandoverParams) -> Policy:
    from agents.constant_velocity import ConstantVelocityAgent
    from agents.reactive import ReactiveConfig

    return ConstantVelocityAgent(ReactiveConfig(horizon=options.horizon, velocity_window=16),
                                 params=params)


def test_one_entry_adds_an_agent_to_every_command_and_the_runner(monkeypatch) -> None:
    """The diff that adds a built-in agent is this one entry."""
    entry = roster.AgentEntry("cv-slow", "Constant velocity (16 frames)", _cv_slow,
                              tracks=("openloop", "closedloop"))
    monkeypatch.setattr(roster, "ROSTER", (*roster.ROSTER, entry))
    assert roster.openloop_methods()[-1] == "cv-slow"
    assert check_methods(["cv-slow"]) == ["cv-slow"]
    assert roster.check_agents(["cv-slow"]) == ["cv-slow"]
    assert roster.default_agents(quick=False)[-1] == "cv-slow"
    assert roster.label("cv-slow") == "Constant velocity (16 frames)"
    src = plugin.resolve("cv-slow")
    assert (src.kind, src.target, src.tracks) == ("method", "cv-slow", ("openloop", "closedloop"))
    options = MethodOptions(workers=1)
    agent = roster.make_agent("cv-slow", HandoverParams(), options)
    assert agent.config.velocity_window == 16
    setting = episodes.Setting("cv-slow", HandoverParams())
    spec = ReceiverSpec("id", "id-0000", 0)
    try:
        row = episodes.run_receiver(setting, agent, spec, dataset=None,  # type: ignore[arg-type]
                                    builtin=roster.entry("cv-slow"))
    finally:
        episodes.clear_envs()
    assert row["agent"] == "cv-slow" and row["env"] == "dynamic" and row["steps"] > 0
    assert row["outcome"] in ("success", "premature_release", "dropped", "unsafe_force", "missed",
                              "unstable", "timeout")


def test_the_runner_keeps_one_env_per_kind_theta_and_keywords() -> None:
    a, b = HandoverParams(), HandoverParams(stiffness=90.0)
    try:
        env = episodes.env_for("dynamic", a, '{"sensing": "ideal"}')
        assert episodes.env_for("dynamic", a, '{"sensing": "ideal"}') is env
        assert env.unwrapped.params == a and env.unwrapped.sensing == "ideal"
        other = episodes.env_for("dynamic", b, '{"sensing": "ideal"}')
        assert other is not env and other.unwrapped.params == b
        static = episodes.env_for("static", a)
        assert static.unwrapped.spec.id.endswith("StaticHandover-v0")
        for k in range(episodes.ENV_CACHE_SIZE):  # the least recently used are closed
            episodes.env_for("dynamic", dataclasses.replace(a, damping=11.0 + k))
        assert episodes.env_for("dynamic", a, '{"sensing": "ideal"}') is not env
    finally:
        episodes.clear_envs()
    with pytest.raises(ValueError, match="env kind must be one of"):
        episodes.make_env("moving", a)
