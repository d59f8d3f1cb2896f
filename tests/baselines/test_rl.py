"""Issue 26: the RL agent (SB3 PPO/SAC) trained in the env against the simulated person.

What is checked: the training receivers never include an evaluation receiver (seed ranges and
folds disjoint by construction), the policy's observation/action mapping and the reward shaping
(numbers), ``train.py rl --quick`` (checkpoint, curve CSV/PNG, resume, refusals), the safe
checkpoint (tampered JSON/safetensors and a pickled SB3 zip: one named error, nothing runs; the
symlink/staging attack of test_security_recovery), bit-identical weights from two processes, and
``evaluate.py closed-loop --quick`` with the RL agents paired against reactive. Over 500 lines
because it is the one test file of the issue, and its checks share the quick checkpoint fixture.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import torch  # noqa: E402

torch.set_num_threads(1)

from planted import PAYLOAD, Untouched, plant  # noqa: E402
from safetensors.torch import load_file, save_file  # noqa: E402

import evaluate  # noqa: E402
import handover_env  # noqa: E402
from baselines.checkpoint_io import CheckpointError  # noqa: E402
from baselines.rl.agent import RLAgent  # noqa: E402
from baselines.rl.config import (  # noqa: E402
    CURVE_SEEDS,
    EVAL_SEED_LIMIT,
    TRAIN_SEED_START,
    RLConfig,
    curve_seed,
    episode_seed,
    training_folds,
)
from baselines.rl.envs import (  # noqa: E402
    HandoverShaping,
    HandoverTrainingEnv,
    PolicyIO,
    make_handover_env,
)
from baselines.rl.files import env_action_space  # noqa: E402
from handover_env.envs.observation import ObsLayout  # noqa: E402
from handover_env.person.synthetic import generate_synthetic  # noqa: E402
from handover_eval.cli import train  # noqa: E402
from handover_eval.cli.closedloop import COUNTS  # noqa: E402
from handover_eval.receivers import FIRST_SEED, fold_of, held_out_folds  # noqa: E402
from handover_eval.rl.run import training_data  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
QUICK = ["rl", "--quick", "--no-progress"]


def _curve(folder: Path) -> list[dict]:
    with (folder / "train_log.csv").open() as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def quick_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rl") / "run"
    assert train.main(QUICK + ["--out", str(out)]) == 0
    return out


# ---------------------------------------------------------------------- disjoint receivers
def test_training_seeds_lie_above_every_evaluation_seed():
    n_max = COUNTS["--walkers"].high  # evaluate.py's largest --walkers
    highest_eval = max(FIRST_SEED.values()) + n_max - 1
    assert highest_eval < EVAL_SEED_LIMIT < TRAIN_SEED_START
    assert curve_seed(0) == TRAIN_SEED_START and curve_seed(CURVE_SEEDS - 1) < episode_seed(
        0, 1, 0, 0)
    seeds = {episode_seed(r, n, i, e) for r in range(3) for n in (1, 2, 4) for i in range(n)
             for e in range(50)}
    assert min(seeds) >= TRAIN_SEED_START + CURVE_SEEDS
    # distinct across envs, episodes and run seeds (for one env count)
    grid = [episode_seed(r, 4, i, e) for r in range(3) for i in range(4) for e in range(100)]
    assert len(set(grid)) == len(grid)
    with pytest.raises(ValueError, match="the learning-curve set has at most 1000 receivers"):
        curve_seed(CURVE_SEEDS)


@pytest.mark.parametrize("k", range(2, 13))
def test_training_folds_are_the_complement_of_the_held_out_folds(k):
    train_f, held = set(training_folds(k)), set(held_out_folds(k))
    assert train_f and not train_f & held and train_f | held == set(range(k))


def test_training_replays_come_from_the_training_folds_only():
    data = generate_synthetic(n=40, ood_fraction=0.2, seed=3)
    config = RLConfig(folds=4, split_seed=0)
    td = training_data(data, config)
    folds = fold_of(data, 4, 0)
    by_id = {ep.source_id: int(folds[i]) for i, ep in enumerate(data)}
    assert td.replay_ids and {by_id[i] for i in td.replay_ids} == set(training_folds(4)) == {0, 1}
    assert len(td.replay_ids) == int(np.isin(folds, [0, 1]).sum())
    assert training_data(data, RLConfig(p_replay=0.0)).replays == []


def test_the_training_env_meets_training_receivers_only():
    data = generate_synthetic(n=12, ood_fraction=0.25, seed=1)
    episodes = [data[i] for i in range(4)]
    config = RLConfig(form="scratch", p_id=0.3, p_ood=0.3, p_replay=0.4, seed=5, n_envs=2,
                      shaping=1.0)
    env = HandoverTrainingEnv(make_handover_env(config), config, 1, None, episodes)
    kinds, seeds = [], []
    for n in range(12):
        kind, seed, options = env.next_receiver()
        kinds.append(kind)
        seeds.append(seed)
        assert seed == episode_seed(5, 2, 1, n) >= TRAIN_SEED_START
        ep = options.get("episode")
        assert (kind == "replay") == any(ep is e for e in episodes)
    assert set(kinds) == {"id", "ood", "replay"}
    env.restart(0)  # the stream is a function of (seed, env, episode)
    assert [env.next_receiver()[1] for _ in range(12)] == seeds
    env.restart(0)
    obs, info = env.reset(seed=0)  # SB3's seed is ignored
    assert info["train_seed"] == seeds[0] and obs.shape == env.observation_space.shape
    obs, reward, *_, info = env.step(np.zeros(4, np.float32))
    terms = info["reward_time"] + info["reward_force"] + info["reward_outcome"]
    assert reward == pytest.approx(terms + info["reward_shaping"])
    env.close()


# ---------------------------------------------------------------------- policy I/O and reward
def test_residual_and_scratch_actions_map_to_bounded_targets():
    box = env_action_space()
    res = PolicyIO.for_env(RLConfig(residual_xyz=0.1, residual_yaw=0.2), box)
    base = np.array([0.3, -0.4, 1.15, -1.0])
    assert np.allclose(res.target(np.array([1, -1, 0.5, 1.0]), base),
                       [0.4, -0.5, 1.2, -0.8], atol=1e-6)
    assert np.allclose(res.target(np.array([9, 0, 0, 0]), base)[0], 0.4)  # action clipped to 1
    near_edge = np.array([0.88, 0.09, 1.59, 3.1])
    assert np.allclose(res.target(np.ones(4), near_edge), box.high)  # clipped to the env box
    scratch = PolicyIO.for_env(RLConfig(form="scratch"), box)
    assert np.allclose(scratch.target(-np.ones(4), None), box.low)
    assert np.allclose(scratch.target(np.ones(4), None), box.high)
    assert np.allclose(scratch.target(np.zeros(4), None), (box.low + box.high) / 2)
    obs = np.zeros(ObsLayout(30).size, np.float32)
    assert res.observation(obs, base).shape == (ObsLayout(30).size + 4,)
    assert scratch.observation(obs, None).shape == (ObsLayout(30).size,)
    assert np.all(np.abs(scratch.observation(obs + 1e6, None)) <= 10)
    with pytest.raises(ValueError, match="observation has"):
        scratch.observation(obs[:-1], None)


def test_shaping_is_potential_based_on_the_bottle_to_hand_distance():
    layout = ObsLayout(30)
    sl = layout.slices()
    parts = {k: np.zeros(s) for k, (_, s) in sl.items()}
    parts["object_pos"] = np.array([0.3, -0.4, 1.2])
    parts["receiver_hand_xyz"] = np.array([0.3, -0.8, 1.5])  # 0.5 m away
    parts["object_held"] = np.array([1.0])
    obs = layout.flatten(parts)
    shaping = HandoverShaping(30, weight=2.0, gamma=0.9)
    assert shaping.potential(obs) == pytest.approx(-1.0, abs=1e-6)
    parts["receiver_hand_xyz"] = np.array([0.3, -0.5, 1.2])  # 0.1 m
    closer = layout.flatten(parts)
    f, phi = shaping.term(-1.0, closer, terminated=False)
    assert phi == pytest.approx(-0.2, abs=1e-6) and f == pytest.approx(0.9 * -0.2 + 1.0)
    assert shaping.term(-0.2, closer, terminated=True) == (pytest.approx(0.2), 0.0)
    parts["gripper_open"] = np.array([1.0])  # released: no potential
    assert shaping.potential(layout.flatten(parts)) == 0.0
    assert HandoverShaping(30, 0.0, 0.9).potential(obs) == 0.0


# ---------------------------------------------------------------------- train.py rl --quick
def test_quick_training_writes_a_checkpoint_curve_and_reward_weights(quick_dir):
    names = {p.name for p in quick_dir.iterdir()}
    assert {"config.json", "model.safetensors", "training_state", "train_log.csv",
            "learning_curve.png", "train_summary.json"} <= names
    assert not any(n.endswith(".zip") or n.endswith(".pkl") for n in names)
    rows = _curve(quick_dir)
    assert [int(r["steps"]) for r in rows] == [0, 128, 256]
    assert set(rows[0]) == {"steps", "success_rate", "handover_time", "return", "episodes",
                            "wall_time_s"}
    assert all(0 <= float(r["success_rate"]) <= 1 for r in rows)
    record = json.loads((quick_dir / "config.json").read_text())
    assert record["type"] == "rl" and record["config"]["algo"] == "ppo"
    assert record["reward"] == {"time_cost": 1.0, "force_threshold": 2.0, "force_scale": 10.0,
                                "success": 10.0, "failure": 10.0, "shaping": 1.0, "gamma": 0.99,
                                "action_change": 0.0, "contact_penalty": 0.0}
    assert record["receivers"]["episode_seeds"][0] >= TRAIN_SEED_START
    assert record["receivers"]["eval_seed_limit"] == EVAL_SEED_LIMIT
    assert (quick_dir / "learning_curve.png").read_bytes()[:4] == b"\x89PNG"
    versions = record["versions"]  # the code that trained it (handover_eval.provenance)
    assert versions["handover_env"] == handover_env.__version__
    assert versions["command"].startswith("python ") and " rl --quick " in versions["command"]
    assert isinstance(versions["dirty"], bool)
    if (ROOT / ".git").exists():
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True,
                              text=True).stdout.strip()
        assert versions["commit"] == head


def test_provenance_is_the_command_as_typed_and_empty_outside_a_checkout(tmp_path, monkeypatch):
    from handover_eval import provenance

    assert provenance.command_line(["/x/y/train.py", "rl", "--out", "a b"]) == (
        "python train.py rl --out 'a b'")
    monkeypatch.setattr(provenance, "ROOT", tmp_path)  # no .git: an installed package
    assert provenance.code_provenance(["train.py", "rl"]) == {
        "commit": "", "dirty": False, "command": "python train.py rl"}


def test_the_loaded_agent_acts_as_the_training_wrapper_does(quick_dir):
    agent = RLAgent.load(quick_dir)
    assert agent.config.form == "residual" and agent.base is not None
    env = make_handover_env(agent.config)
    obs, _ = env.reset(seed=3)
    agent.reset()
    a1 = agent.act(obs)
    base_target = agent.base.act(obs)  # the same as act(): base + bounded correction
    assert a1.shape == (4,) and a1.dtype == np.float32
    assert np.all(np.abs(a1[:3] - base_target[:3]) <= 0.15 + 1e-6)
    assert abs(a1[3] - base_target[3]) <= 0.3 + 1e-6
    # a policy, not a predictor: it has no open-loop prediction to stub
    from agents.base import Policy, Predictor

    assert isinstance(agent, Policy) and not isinstance(agent, Predictor)
    assert not hasattr(agent, "predict")
    env.close()


def test_resume_extends_the_run_and_refuses_other_settings(quick_dir, tmp_path, capsys):
    run = shutil.copytree(quick_dir, tmp_path / "run")
    assert train.main(QUICK + ["--out", str(run)]) == 2
    assert "already holds a RL run; pass --resume" in capsys.readouterr().err
    assert train.main(QUICK + ["--out", str(run), "--resume", "--lr", "1e-3"]) == 2
    assert "its config differs in ['learning_rate']" in capsys.readouterr().err
    assert train.main(QUICK + ["--out", str(run), "--resume", "--steps", "384"]) == 0
    rows = _curve(run)
    assert [int(r["steps"]) for r in rows] == [0, 128, 256, 384]
    state = json.loads((run / "training_state" / "state.json").read_text())
    assert state["steps"] == 384 and sum(state["episodes"]) >= int(rows[2]["episodes"])


def test_bad_flags_are_one_line_errors(tmp_path, capsys):
    assert train.main(QUICK + ["--out", str(tmp_path / "a"), "--p-replay", "0.9",
                               "--p-ood", "0.5"]) == 2
    assert "--p-replay and --p-ood" in capsys.readouterr().err
    assert train.main(QUICK + ["--out", str(tmp_path / "b"), "--sensing", "bogus"]) == 2
    err = capsys.readouterr().err
    assert "sensing" in err and "\n" not in err.strip()
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "notes.txt").write_text("mine")
    assert train.main(QUICK + ["--out", str(tmp_path / "c")]) == 2
    assert "holds no checkpoint of this project" in capsys.readouterr().err


# ---------------------------------------------------------------------- safe checkpoint
def _json_edit(key_path: list, value):
    def edit(folder: Path) -> None:
        d = json.loads((folder / "config.json").read_text())
        node = d
        for k in key_path[:-1]:
            node = node[k]
        if value is KeyError:
            del node[key_path[-1]]
        else:
            node[key_path[-1]] = value
        (folder / "config.json").write_text(json.dumps(d))
    return edit


def _tensor_edit(fn):
    def edit(folder: Path) -> None:
        t = load_file(folder / "model.safetensors")
        fn(t)
        save_file(t, folder / "model.safetensors")
    return edit


def _nan(t):
    k = next(k for k in t if k.startswith("policy.") and t[k].dim() == 2)
    t[k] = t[k].clone()
    t[k][0, 0] = math.nan


def _shape(t):
    k = next(k for k in t if k.startswith("policy.") and t[k].dim() == 2)
    t[k] = torch.zeros(t[k].shape[0] + 1, t[k].shape[1])


def _scale(t):
    t["io.scale"] = t["io.scale"].clone() * 2


def _extra(t):
    t["policy.evil"] = torch.zeros(3)


def _pickle_as_weights(folder: Path) -> None:
    import pickle

    class Boom:
        def __reduce__(self):
            return (exec, (PAYLOAD,))

    (folder / "model.safetensors").write_bytes(pickle.dumps(Boom()))


TAMPERED = {
    "not-json": (lambda f: (f / "config.json").write_text("{not json"), "not valid JSON"),
    "wrong-type": (_json_edit(["type"], "bc_mlp"), "holds a 'bc_mlp' checkpoint, not 'rl'"),
    "format": (_json_edit(["format"], 99), "checkpoint format 99"),
    "mistyped-field": (_json_edit(["config", "n_envs"], "2"), "config field n_envs = '2'"),
    "bool-as-int": (_json_edit(["config", "steps"], True), "config field steps = True"),
    "unknown-field": (_json_edit(["config", "exec"], "os.system"), "unknown \\['exec'\\]"),
    "missing-field": (_json_edit(["config", "algo"], KeyError), "missing \\['algo'\\]"),
    "bad-value": (_json_edit(["config", "algo"], "dqn"), "invalid config"),
    "reward-missing": (_json_edit(["reward", "success"], KeyError), "reward must hold"),
    "reward-nan": (_json_edit(["reward", "success"], "NaN"), "reward must hold"),
    "replay-ids": (_json_edit(["receivers", "replay_ids"], "all"), "replay_ids must be a list"),
    "extra-section": (_json_edit(["code"], "print(1)"), "expected the fields"),
    "truncated": (lambda f: (f / "model.safetensors").write_bytes(
        (f / "model.safetensors").read_bytes()[:100]), "not a readable safetensors file"),
    "pickle-as-weights": (_pickle_as_weights, "not a readable safetensors file"),
    "nan-weight": (_tensor_edit(_nan), "holds NaN or inf"),
    "wrong-shape": (_tensor_edit(_shape), "expected torch.float32"),
    "extra-tensor": (_tensor_edit(_extra), "unexpected \\['policy.evil'\\]"),
    "normalisation": (_tensor_edit(_scale), "differ from this code's observation normalisation"),
    "no-weights": (lambda f: (f / "model.safetensors").unlink(), "model.safetensors: missing"),
}


@pytest.mark.parametrize("name", sorted(TAMPERED))
def test_a_tampered_checkpoint_is_one_named_error_and_nothing_runs(quick_dir, tmp_path, name):
    folder = shutil.copytree(quick_dir, tmp_path / "ckpt")
    tamper, message = TAMPERED[name]
    tamper(folder)
    outside = tmp_path / "site-packages"
    outside.mkdir()
    (outside / "victim.pth").write_text("ORIGINAL")
    untouched = Untouched(outside, folder)
    cwd = os.getcwd()
    os.chdir(tmp_path)  # the payload would write MARKER here
    try:
        with pytest.raises(CheckpointError, match=message) as info:
            RLAgent.load(folder)
    finally:
        os.chdir(cwd)
    assert "\n" not in str(info.value)
    assert not (tmp_path / "MARKER").exists()
    untouched.check()


def test_a_pickled_sb3_zip_beside_the_checkpoint_is_never_read(quick_dir, tmp_path):
    """SB3's own .zip holds cloudpickled entries: the loader never opens one."""
    import pickle
    import zipfile

    class Boom:
        def __reduce__(self):
            return (exec, (PAYLOAD,))

    folder = shutil.copytree(quick_dir, tmp_path / "ckpt")
    with zipfile.ZipFile(folder / "model.zip", "w") as z:
        z.writestr("data", pickle.dumps(Boom()))
        z.writestr("policy.pth", pickle.dumps(Boom()))
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        agent = RLAgent.load(folder)
    finally:
        os.chdir(cwd)
    assert agent.config.form == "residual" and not (tmp_path / "MARKER").exists()


@pytest.fixture
def outside(tmp_path) -> Path:
    site = tmp_path / "site-packages"
    site.mkdir()
    (site / "victim.pth").write_text("ORIGINAL")
    return site


def test_loading_a_planted_rl_checkpoint_writes_nothing(quick_dir, tmp_path, outside):
    folder = shutil.copytree(quick_dir, tmp_path / "ckpt")
    plant(folder, outside)
    untouched = Untouched(outside, folder)
    with pytest.raises(CheckpointError, match="an interrupted checkpoint write") as info:
        RLAgent.load(folder)
    assert "--resume" in str(info.value)
    untouched.check()
    (folder / ".staging" / "COMMIT.json").unlink()  # uncommitted: ignored, the checkpoint loads
    untouched = Untouched(outside, folder)
    assert RLAgent.load(folder).config.form == "residual"
    untouched.check()


def test_an_rl_weights_file_linked_out_of_the_folder_is_refused(quick_dir, tmp_path, outside):
    folder = shutil.copytree(quick_dir, tmp_path / "ckpt")
    shutil.move(folder / "model.safetensors", outside / "model.safetensors")
    (folder / "model.safetensors").symlink_to(outside / "model.safetensors")
    untouched = Untouched(outside, folder)
    with pytest.raises(CheckpointError, match="model.safetensors: a symbolic link out of"):
        RLAgent.load(folder)
    untouched.check()


def test_rl_resume_refuses_a_planted_commit_and_changes_nothing(quick_dir, tmp_path, outside,
                                                                capsys):
    folder = shutil.copytree(quick_dir, tmp_path / "run")
    plant(folder, outside)
    untouched = Untouched(outside, folder)
    capsys.readouterr()
    assert train.main(QUICK + ["--out", str(folder), "--resume", "--steps", "384"]) == 2
    assert f"commit entry 'lnk/x.pth': {folder / 'lnk'} is a symbolic link" in (
        capsys.readouterr().err)
    untouched.check()


# ---------------------------------------------------------------------- reproducibility
def _reactive():
    from agents.reactive import ReactiveAgent

    return ReactiveAgent()


#: The levers of issue 36 on: PPO with gSDE, the action filter, the last action, the privileged
#: critic and both penalties on the cv base; SAC from scratch with pink noise and a warm start.
LEVERS = dict(base="cv", use_sde=True, sde_sample_freq=4, action_tau=0.1, last_actions=1,
              privileged_critic=True, action_change=0.5, contact_penalty=1.0)
SAC_LEVERS = dict(algo="sac", form="scratch", action_noise="pink", warm_start="cv",
                  warm_start_episodes=1, warm_start_epochs=2, steps=96, n_steps=32,
                  eval_every=96)
TRAIN_TINY = f"""
import sys, torch
from baselines.rl.config import RLConfig
from baselines.rl.train import train_policy
if __name__ == "__main__":
    common = dict(steps=256, n_envs=2, n_steps=64, batch_size=32, n_epochs=2, net_arch=(16,),
                  eval_every=256, curve_episodes=1, p_replay=0.0, seed=7)
    train_policy(RLConfig(**{{**common, **{LEVERS!r}}}), sys.argv[1], progress=False)
    train_policy(RLConfig(**{{**common, **{SAC_LEVERS!r}}}), sys.argv[1] + "-sac",
                 progress=False)
"""


def test_same_seed_and_envs_give_the_same_weights_bit_for_bit(tmp_path):
    """Two tiny PPO runs and two tiny SAC runs (2 SubprocVecEnv envs each), every lever of
    issue 36 on, in separate processes."""
    script = tmp_path / "tiny.py"
    script.write_text(TRAIN_TINY)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    procs = [subprocess.Popen([sys.executable, str(script), str(tmp_path / f"run{i}")], env=env,
                              cwd=tmp_path, stderr=subprocess.PIPE) for i in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=900)  # a loaded machine once took over 300 s
        assert p.returncode == 0, err.decode()[-2000:]
    for suffix in ("-sac", ""):
        a, b = (load_file(tmp_path / f"run{i}{suffix}" / "model.safetensors") for i in range(2))
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    from stable_baselines3.common.vec_env import DummyVecEnv

    from baselines.rl.envs import training_env
    from baselines.rl.policy import build_model

    cfg = RLConfig(steps=256, n_envs=1, n_steps=64, batch_size=32, n_epochs=2, net_arch=(16,),
                   eval_every=256, curve_episodes=1, p_replay=0.0, seed=7, **LEVERS)
    vec = DummyVecEnv([lambda: training_env(cfg, 0, _reactive(), [])])
    initial = build_model(cfg, vec).policy.state_dict()
    vec.close()
    assert any(not torch.equal(a[f"policy.{k}"], v) for k, v in initial.items())  # it learned
    state = json.loads((tmp_path / "run0" / "training_state" / "state.json").read_text())
    assert state["steps"] == 256 and state["episodes"] == json.loads(
        (tmp_path / "run1" / "training_state" / "state.json").read_text())["episodes"]


# ---------------------------------------------------------------------- closed loop
def test_the_agent_refuses_receivers_it_trained_on(quick_dir):
    agent = RLAgent.load(quick_dir)
    agent.trained_replays = frozenset({"rec-7"})
    with pytest.raises(ValueError, match="trained on the recording 'rec-7'"):
        agent.check_receiver("replay", "rec-7", 3)
    with pytest.raises(ValueError, match="training range"):
        agent.check_receiver("id", "id-x", TRAIN_SEED_START)
    agent.check_receiver("replay", "rec-8", 3)
    agent.check_receiver("ood", "ood-0001", 10_001)
    low, high = agent.record["receivers"]["episode_seeds"]
    with pytest.raises(ValueError, match="training range"):
        agent.check_receiver("id", "id-x", high)
    agent.check_receiver("id", "id-x", 200_000_000)  # a benchmark test seed: never drawn
    agent.record = {}  # a policy with no record: every seed from TRAIN_SEED_START on
    with pytest.raises(ValueError, match="training range"):
        agent.check_receiver("id", "id-x", 200_000_000)


def test_closed_loop_refuses_replays_of_the_training_folds(tmp_path, capsys):
    """A policy trained on replays of folds 0..k//2-1 is refused on any of them."""
    data = generate_synthetic(n=30, ood_fraction=0.2, seed=0)  # evaluate.py --quick's data
    config = RLConfig(form="scratch", folds=3, steps=64, n_envs=1, n_steps=32, batch_size=32,
                      n_epochs=1, net_arch=(8,), eval_every=64, curve_episodes=1, p_replay=0.5)
    from baselines.rl.train import train_policy

    td = training_data(data, config)
    train_policy(config, tmp_path / "ckpt", td, progress=False)
    argv = ["closed-loop", "--quick", "--no-progress", "--agents", "reactive", "rl-scratch",
            "--rl-checkpoint", str(tmp_path / "ckpt"), "--replay-folds", "0",
            "--out", str(tmp_path / "out"), "--checkpoints", str(tmp_path / "cache")]
    assert evaluate.main(argv) == 2
    err = capsys.readouterr().err
    assert "rl-scratch" in err and "held-out folds only" in err


def test_quick_closed_loop_pairs_both_rl_agents_against_reactive(closed_loop_every_agent):
    """``closed-loop --quick`` with every agent, the RL ones trained on the spot (the session's
    shared run, tests/conftest.py)."""
    out = closed_loop_every_agent / "out"
    with (out / "closed_loop_episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    by_agent = {a: [r for r in rows if r["agent"] == a] for a in ("reactive", "rl-residual",
                                                                   "rl-scratch")}
    receivers = {a: sorted((r["set"], r["receiver"]) for r in rs) for a, rs in by_agent.items()}
    assert receivers["rl-residual"] == receivers["rl-scratch"] == receivers["reactive"]
    assert len(receivers["reactive"]) == 7  # 2 ID + 2 OOD walkers, 3 replays
    assert all(r["outcome"] for rs in by_agent.values() for r in rs)
    with (out / "closed_loop_paired.csv").open() as fh:
        paired = {r["agent"] for r in csv.DictReader(fh)}
    assert {"rl-residual", "rl-scratch"} <= paired
    text = (out / "closed_loop.md").read_text()
    assert "RL residual" in text and "RL from scratch" in text


def test_a_residual_on_ours_reloads_only_with_the_episodes_its_base_was_fitted_on(tmp_path):
    out = tmp_path / "ours"
    assert train.main(QUICK + ["--base", "ours", "--p-replay", "0.3", "--out", str(out)]) == 0
    record = json.loads((out / "config.json").read_text())
    data = train.load_data(None, True, 0)  # --quick's data
    td = training_data(data, _config(out))
    assert record["receivers"]["base_fit_ids"] == sorted(ep.source_id for ep in td.base_fit)
    assert record["receivers"]["replay_ids"] == sorted(td.replay_ids) and td.replay_ids
    agent = RLAgent.load(out, fit_data=td.base_fit)
    assert type(agent.base).__name__ == "NonparametricAgent"
    with pytest.raises(CheckpointError, match="its SPGP base was fitted on"):
        RLAgent.load(out, fit_data=data.subset([0, 1]))


def _config(folder: Path) -> RLConfig:
    from baselines.rl.files import read_record

    return read_record(folder)[1]
