"""Issue 36: the RL levers (exploration, action filter, observation, asymmetric critic, cv base,
warm start, penalties) and the seed statistics (IQM, stratified bootstrap).

What is checked, in numbers: the filter's step response and the memory's order; pink noise's
spectrum and seeding; the two penalties against hand-computed values (the receiving hand left
out, each region weighed by its ISO/TS 15066 limit); the privileged state against the simulator
and an actor that never reads it; the warm start's seeds and its fit; a ``--quick`` run of PPO
with every lever on and of SAC from scratch with pink noise and a warm start (trained, loaded,
acting as the wrapper does); IQM and the stratified bootstrap against closed forms.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

torch.set_num_threads(1)

from baselines.rl.action_filter import DT, ActionMemory, filter_gain  # noqa: E402
from baselines.rl.agent import RLAgent, make_base  # noqa: E402
from baselines.rl.config import (  # noqa: E402
    MAX_STEPS,
    RUN_STRIDE,
    TRAIN_SEED_START,
    RLConfig,
    episode_seed,
    warm_start_seed,
)
from baselines.rl.envs import (  # noqa: E402
    HandoverTrainingEnv,
    PolicyIO,
    make_handover_env,
    training_observation_space,
)
from baselines.rl.files import env_action_space  # noqa: E402
from baselines.rl.noise import coloured_noise, pink_noise  # noqa: E402
from baselines.rl.penalties import (  # noqa: E402
    BEYOND_HAND,
    PAIN_ONSET_N,
    action_change_cost,
    contact_cost,
    segment_forces,
)
from baselines.rl.policy import build_policy  # noqa: E402
from baselines.rl.privileged import privileged_normalisation, privileged_state  # noqa: E402
from handover_env.envs.observation import ObsLayout  # noqa: E402
from handover_env.person.skeleton import SEGMENTS  # noqa: E402
from handover_eval.cli import train  # noqa: E402
from handover_eval.rl.statistics import curve_band, iqm, stratified_bootstrap_ci  # noqa: E402

#: The smallest run that trains: one PPO rollout (64 steps), 64 SAC updates after its 64
#: learning-starts; one curve receiver at the start and the end.
TINY = ["--steps", "64", "--eval-every", "64", "--curve-episodes", "1"]
LEVERS = ["--base", "cv", "--use-sde", "--sde-sample-freq", "4", "--action-tau", "0.1",
          "--last-actions", "2", "--privileged-critic", "--action-change", "0.5",
          "--contact-penalty", "1"]
SAC_SCRATCH = ["--algo", "sac", "--base", "none", "--warm-start", "reactive",
               "--action-noise", "pink", "--use-sde", "--last-actions", "1"]


@pytest.fixture(scope="module")
def lever_dirs(tmp_path_factory) -> dict:
    """``train.py rl --quick`` with every PPO lever, and SAC scratch with pink noise, gSDE and a
    reactive warm start."""
    root = tmp_path_factory.mktemp("levers")
    out = {"ppo": root / "ppo", "sac": root / "sac"}
    assert train.main(["rl", "--quick", "--no-progress", "--out", str(out["ppo"]), *TINY,
                       *LEVERS]) == 0
    assert train.main(["rl", "--quick", "--no-progress", "--out", str(out["sac"]), *TINY,
                       "--steps", "128", "--eval-every", "128", *SAC_SCRATCH]) == 0
    return out


@pytest.fixture(scope="module")
def paper_env():
    """One env of the paper profile, shared (building one is most of a test's time)."""
    env = make_handover_env(RLConfig(sensing="paper"))
    yield env
    env.close()


# ---------------------------------------------------------------------- the action filter
def test_the_filter_is_first_order_with_its_time_constant():
    alpha = filter_gain(0.1)
    assert alpha == pytest.approx(DT / (0.1 + DT)) and filter_gain(0.0) == 1.0
    mem = ActionMemory(0.1, 3, np.zeros(4))
    steps = [mem.apply(np.ones(4))[0] for _ in range(10)]
    assert steps == pytest.approx([1 - (1 - alpha) ** n for n in range(1, 11)])
    assert alpha == 0.25  # tau = 0.1 s = 3 steps of 1/30 s: alpha = 1 / (3 + 1)
    past = mem.observation().reshape(3, 4)[:, 0]  # most recent first
    assert past == pytest.approx(steps[-1:-4:-1])
    mem.reset()
    assert np.all(mem.observation() == 0) and np.all(mem.u == 0)
    raw = ActionMemory(0.0, 0, np.zeros(4))
    assert raw.apply(np.array([0.3, -2, 1, 0])) == pytest.approx([0.3, -1, 1, 0])  # clipped
    assert raw.observation().size == 0


def test_the_scratch_filter_starts_at_the_ready_pose():
    io = PolicyIO.for_env(RLConfig(form="scratch", action_tau=0.2), env_action_space())
    start = io.memory().u
    assert io.target(start, None)[:3] == pytest.approx([0.3, -0.4, 1.15], abs=1e-5)
    assert io.action_of(io.target(np.array([0.2, -0.1, 0.3, 0.0]), None), None) == pytest.approx(
        [0.2, -0.1, 0.3, 0.0], abs=1e-5)
    res = PolicyIO.for_env(RLConfig(action_tau=0.2), env_action_space())
    assert np.all(res.memory().u == 0)


# ---------------------------------------------------------------------- pink noise
def test_pink_noise_has_a_one_over_f_spectrum_and_is_seeded():
    x = coloured_noise(1.0, (4, 4096), np.random.default_rng(0))
    assert x.std(axis=1) == pytest.approx(np.ones(4)) and abs(x.mean()) < 0.2
    psd = (np.abs(np.fft.rfft(x, axis=1)) ** 2).mean(axis=0)[1:]
    f = np.fft.rfftfreq(4096)[1:]
    slope = np.polyfit(np.log(f), np.log(psd), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.15)
    white = coloured_noise(0.0, (4, 4096), np.random.default_rng(0))
    w_psd = (np.abs(np.fft.rfft(white, axis=1)) ** 2).mean(axis=0)[1:]
    assert abs(np.polyfit(np.log(f), np.log(w_psd), 1)[0]) < 0.15
    a, b = pink_noise(0.2, 4, 2, seed=5), pink_noise(0.2, 4, 2, seed=5)
    seq_a = np.array([a() for _ in range(300)])
    assert seq_a.shape == (300, 2, 4) and np.array_equal(seq_a, [b() for _ in range(300)])
    assert not np.array_equal(seq_a[:, 0], seq_a[:, 1])  # each env its own stream
    assert seq_a.std() == pytest.approx(0.2, rel=0.3)


# ---------------------------------------------------------------------- penalties
def test_the_action_change_penalty_in_numbers():
    assert action_change_cost(2.0, [1, 0, 0, 0], [0, 0, 0, 0]) == pytest.approx(-0.5)
    assert action_change_cost(1.0, np.ones(4), -np.ones(4)) == pytest.approx(-4.0)
    assert action_change_cost(0.0, np.ones(4), -np.ones(4)) == 0.0


def test_the_contact_penalty_weighs_each_region_by_its_iso_limit_and_spares_the_hand(paper_env):
    names = [s.name for s in SEGMENTS]
    forces = np.zeros(len(SEGMENTS))
    forces[names.index("hand_r")] = 500.0  # the handover itself: free
    assert contact_cost(1.0, forces) == 0.0
    forces[names.index("forearm_r")] = 80.0  # lower arm: 160 N limit
    forces[names.index("torso")] = 140.0  # chest: 140 N
    assert PAIN_ONSET_N[names.index("forearm_r")] == 160.0
    assert contact_cost(3.0, forces) == pytest.approx(-3.0 * DT * (0.5 + 1.0))
    assert BEYOND_HAND.sum() == len(SEGMENTS) - 1
    paper_env.reset(seed=1)
    f = segment_forces(paper_env)
    assert f.shape == (len(SEGMENTS),) and np.all(f >= 0)


def test_the_wrapper_reports_every_reward_term_in_info(paper_env):
    config = RLConfig(base="cv", action_change=1.0, contact_penalty=1.0, action_tau=0.1,
                      last_actions=1, privileged_critic=True, sensing="paper")
    env = HandoverTrainingEnv(paper_env, config, 0, make_base(config))
    obs, _ = env.reset()
    assert set(obs) == {"actor", "privileged"} and env.observation_space["actor"].contains(
        obs["actor"])
    total = 0.0
    for a in (np.ones(4), -np.ones(4)):
        obs, reward, *_, info = env.step(a.astype(np.float32))
        terms = sum(info[f"reward_{t}"] for t in ("time", "force", "outcome", "shaping",
                                                  "action_change", "contact"))
        assert reward == pytest.approx(terms)
        total += info["reward_action_change"]
    alpha = filter_gain(0.1)  # the filtered actions of the two steps, from 0
    u1 = alpha * np.ones(4)
    u2 = u1 + alpha * (-np.ones(4) - u1)
    assert total == pytest.approx(-(u1 @ u1) / 4 - ((u2 - u1) @ (u2 - u1)) / 4)
    assert obs["actor"][-4:] == pytest.approx(u2)  # its last action, after the filter


# ---------------------------------------------------------------------- asymmetric critic
def test_the_privileged_state_is_the_simulators_and_the_actor_never_reads_it(paper_env):
    env = paper_env
    env.reset(seed=2)
    for _ in range(5):
        env.step(np.array([0.3, -0.4, 1.15, -1.57], np.float32))
    u = env.unwrapped
    raw = privileged_state(env)
    body = u.ids.receiver.body
    assert raw[:3] == pytest.approx(u.data.xpos[body.bodies[0]])
    assert raw[9:12] == pytest.approx(u.wrist.f_true)
    assert raw[12:].sum() == 1.0 and raw.shape == privileged_normalisation()[0].shape
    for algo in ("ppo", "sac"):
        cfg = RLConfig(algo=algo, privileged_critic=True, use_sde=True, net_arch=(8,))
        io = PolicyIO.for_env(cfg, env_action_space())
        space = training_observation_space(cfg, io)
        policy = build_policy(cfg, space, io.action_space)
        x = space.sample()
        a1, _ = policy.predict(x, deterministic=True)
        a2, _ = policy.predict({**x, "privileged": np.zeros_like(x["privileged"])},
                               deterministic=True)
        assert np.array_equal(a1, a2)
        if algo == "ppo":  # the critic does read it
            obs = {k: torch.as_tensor(v)[None] for k, v in x.items()}
            zero = {**obs, "privileged": torch.zeros_like(obs["privileged"])}
            assert not torch.equal(policy.predict_values(obs), policy.predict_values(zero))


# ---------------------------------------------------------------------- warm start, seeds
def test_warm_start_seeds_never_meet_a_training_episode():
    top = TRAIN_SEED_START + 1000 + RUN_STRIDE - 1
    assert warm_start_seed(0, 0) == top and warm_start_seed(0, 9_999) == top - 9_999
    most_episodes = 2 * MAX_STEPS + 64
    assert episode_seed(0, 1, 0, most_episodes) < warm_start_seed(0, 9_999)
    assert warm_start_seed(1, 9_999) > warm_start_seed(0, 0)  # the next run's block
    with pytest.raises(ValueError, match="at most 10000 episodes"):
        warm_start_seed(0, 10_000)
    with pytest.raises(ValueError, match="warm_start is for the scratch form"):
        RLConfig(warm_start="reactive", warm_start_episodes=2)
    with pytest.raises(ValueError, match="action_noise \\(pink\\) is for SAC"):
        RLConfig(action_noise="pink")


def test_quick_runs_with_the_levers_record_them_and_act_as_trained(lever_dirs, paper_env):
    ppo = json.loads((lever_dirs["ppo"] / "config.json").read_text())
    c = ppo["config"]
    assert (c["base"], c["use_sde"], c["sde_sample_freq"], c["action_tau"], c["last_actions"],
            c["privileged_critic"]) == ("cv", True, 4, 0.1, 2, True)
    assert ppo["reward"]["action_change"] == 0.5 and ppo["reward"]["contact_penalty"] == 1.0
    assert ppo["io"]["obs_size"] == ObsLayout(30).size + 4 + 2 * 4  # base target, 2 actions
    assert "privileged" in ppo["io"]["normalisation"]
    sac = json.loads((lever_dirs["sac"] / "config.json").read_text())
    s = sac["config"]
    assert (s["form"], s["warm_start"], s["warm_start_episodes"], s["action_noise"]) == (
        "scratch", "reactive", 2, "pink")
    assert sac["receivers"]["warm_start_seeds"] == [warm_start_seed(0, 1), warm_start_seed(0, 0)]
    rows = (lever_dirs["sac"] / "train_log.csv").read_text().splitlines()
    assert float(rows[1].split(",")[1]) > 0  # warm-started: it hands over at step 0
    for folder in lever_dirs.values():
        agent = RLAgent.load(folder)
        env = paper_env
        obs, _ = env.reset(seed=4)
        agent.reset()
        targets = [agent.act(obs)]
        obs, *_ = env.step(targets[0])
        targets.append(agent.act(obs))
        assert all(t.shape == (4,) and np.all(np.isfinite(t)) for t in targets)
        assert np.any(agent.memory.u != agent.io.start_action())  # the filter moved
    assert type(RLAgent.load(lever_dirs["ppo"]).base).__name__ == "ConstantVelocityAgent"


# ---------------------------------------------------------------------- IQM, bootstrap
def test_iqm_is_the_25_percent_trimmed_mean():
    assert iqm(np.arange(1, 9)) == pytest.approx(4.5)  # 3, 4, 5, 6
    assert iqm([[0.0], [0.0], [0.0], [10.0]]) == 0.0
    assert iqm([[1.0, 2.0], [3.0, 4.0]]) == pytest.approx(2.5)
    with pytest.raises(ValueError, match="every one finite"):
        iqm([1.0, math.nan])


def test_the_stratified_bootstrap_resamples_runs_within_each_task():
    """Two runs, two tasks, scores [[0, 1], [1, 0]], the mean: resampling the runs within each
    task independently gives means 0, 1/4, 1/2, 3/4, 1 with probabilities 1, 4, 6, 4, 1 / 16,
    so the 80 % interval is [1/4, 3/4]; resampling whole runs would always give 1/2."""
    x = np.array([[0.0, 1.0], [1.0, 0.0]])
    point, low, high = stratified_bootstrap_ci(x, np.mean, reps=4000, level=0.8, seed=1)
    assert (point, low, high) == (0.5, 0.25, 0.75)
    same = np.array([[2.0, 5.0], [2.0, 5.0], [2.0, 5.0]])  # no spread within a task: no width
    assert stratified_bootstrap_ci(same, iqm, reps=200) == (3.5, 3.5, 3.5)
    a = stratified_bootstrap_ci(np.random.default_rng(0).normal(size=(3, 4)), seed=7)
    assert a == stratified_bootstrap_ci(np.random.default_rng(0).normal(size=(3, 4)), seed=7)
    assert a[1] <= a[0] <= a[2]
    looped = stratified_bootstrap_ci(np.random.default_rng(0).normal(size=(3, 4)),
                                     lambda r: iqm(r), seed=7)  # a scipy trim_mean each
    assert looped == pytest.approx(a, abs=1e-12)
    mid, lo, hi = curve_band([[0.1, 0.5, 0.9], [0.1, 0.7, 0.9, 1.0]], reps=100)
    assert mid.shape == (3,) and mid[0] == pytest.approx(0.1) and lo[1] <= mid[1] <= hi[1]


# ---------------------------------------------------------------------- benchmark row
def test_the_benchmark_scores_a_checkpoint_on_the_closed_loop_track(lever_dirs, tmp_path):
    import csv

    import evaluate
    from baselines.rl.benchmark import rl_agent

    out = tmp_path / "bench"
    argv = ["benchmark", "--quick", "--no-progress", "--agent", "baselines.rl.benchmark:rl_agent",
            "--agent-config", json.dumps({"checkpoint": str(lever_dirs["ppo"])}),
            "--tracks", "closedloop", "--name", "rl-levers", "--workers", "1", "--out", str(out)]
    assert evaluate.main(argv) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["agent"]["name"] == "rl-levers" and result["tracks"] == ["closedloop"]
    assert result["agent"]["config"]["config"]["base"] == "cv"
    with (out / "closedloop_episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    mine = sorted(r["receiver"] for r in rows if r["agent"] == "rl-levers")
    assert mine and mine == sorted(r["receiver"] for r in rows if r["agent"] == "reactive")
    with pytest.raises(ValueError, match="--tracks closedloop"):
        rl_agent(str(lever_dirs["ppo"])).predict(np.zeros((30, 2)))


def test_several_seeds_write_their_curves_with_the_iqm_band(tmp_path):
    from handover_eval.rl.output import SEEDS_PNG, SEEDS_SUMMARY, write_seeds

    states = [{"curve": [{"steps": s, "success_rate": 0.5 + 0.1 * i + 0.1 * k,
                          "return": float(i), "handover_time": math.nan}
                         for k, s in enumerate((0, 64))]} for i in range(3)]
    write_seeds(tmp_path, states, RLConfig())
    body = json.loads((tmp_path / SEEDS_SUMMARY).read_text())
    assert body["seeds"] == 3 and body["end_success_rate"]["iqm"] == pytest.approx(0.7)
    assert body["start_return"] == {"iqm": 1.0, "ci95": [0.0, 2.0]}  # 3 seeds: IQM = the mean
    assert (tmp_path / SEEDS_PNG).read_bytes()[:4] == b"\x89PNG"
