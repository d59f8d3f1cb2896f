"""Issue 32, R5 and R12: an RL checkpoint's resource bounds and its resume state.

Each crafted input is built here, from a checkpoint written in a few seconds without training
(the policy of a config, its record, its training state): a ``config.json`` asking for a huge
split, network or history, a weights file over its config's exact size or with a lying header,
a tampered ``training_state/state.json``. Each ends in one ``CheckpointError`` (or one line of
``train.py`` / ``evaluate.py``, status 2) naming the file and the field, within a time bound,
with nothing trained, run or written. Over 500 lines because every check crafts from the same
few-second checkpoints and refusal helpers (``scratch``, ``_copy``, ``_timed_refusal``): one
threat, the RL checkpoint folder, in one file.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import time
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import torch  # noqa: E402

torch.set_num_threads(1)

import evaluate  # noqa: E402
from baselines.checkpoint_io import CheckpointError  # noqa: E402
from baselines.rl.agent import RLAgent, make_base  # noqa: E402
from baselines.rl.config import MAX_POLICY_PARAMS, QUICK, RLConfig  # noqa: E402
from baselines.rl.envs import (  # noqa: E402
    PolicyIO,
    make_handover_env,
    training_observation_space,
)
from baselines.rl.files import (  # noqa: E402
    CONFIG_REWARD_KEYS,
    REWARD_KEYS,
    env_action_space,
    record_of,
    write_checkpoint,
)
from baselines.rl.layout import checkpoint_layout, parameter_count, policy_layout  # noqa: E402
from baselines.rl.policy import build_policy  # noqa: E402
from handover_eval.cli import train  # noqa: E402
from handover_eval.rl.output import write_summary  # noqa: E402

#: A crafted file must be refused within this many seconds (the real load of a tiny policy takes
#: a fraction of one; a 1e9-fold split or a 20000 x 20000 network took minutes or a MemoryError).
FAST_S = 3.0
QUICK_ARGS = ["rl", "--quick", "--no-progress"]


def snapshot(folder: Path) -> dict[str, tuple]:
    """Every file under ``folder`` (but the lock): its size, mtime and (under 64 MiB) SHA-256."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and p.name != ".lock":
            st = p.stat()
            digest = hashlib.sha256(p.read_bytes()).hexdigest() if st.st_size < 1 << 26 else ""
            out[str(p.relative_to(folder))] = (st.st_size, st.st_mtime_ns, digest)
    return out


def _record(config: RLConfig, io: PolicyIO, training: dict) -> dict:
    reward = {k: 1.0 for k in REWARD_KEYS} | {k: getattr(config, k) for k in CONFIG_REWARD_KEYS}
    receivers = {"replay_ids": [], "base_fit_ids": []}
    return record_of(config, io, reward, receivers, training)


def write_rl_checkpoint(folder: Path, config: RLConfig) -> Path:
    """A loadable RL checkpoint of ``config``'s freshly built policy (no training)."""
    io = PolicyIO.for_env(config, env_action_space())
    policy = build_policy(config, training_observation_space(config, io), io.action_space)
    folder.mkdir(parents=True)
    write_checkpoint(folder, policy, io,
                     _record(config, io, {"steps": 0, "episodes": 0, "wall_time_s": 0.0}))
    return folder


def edit_config(folder: Path, section: str, field: str, value) -> None:
    d = json.loads((folder / "config.json").read_text())
    d[section][field] = value
    (folder / "config.json").write_text(json.dumps(d))


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    config = RLConfig(form="scratch", net_arch=(16, 16), steps=256, n_envs=1, n_steps=64,
                      batch_size=32)
    return write_rl_checkpoint(tmp_path_factory.mktemp("rl") / "scratch", config)


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    return Path(shutil.copytree(src, dst))


def _timed_refusal(folder: Path, match: str) -> str:
    t0 = time.perf_counter()
    with pytest.raises(CheckpointError, match=match) as info:
        RLAgent.load(folder)
    elapsed = time.perf_counter() - t0
    assert elapsed < FAST_S, f"refused after {elapsed:.1f} s"
    message = str(info.value)
    assert "\n" not in message and len(message) < 400
    return message


# ---------------------------------------------------------------------- the layout
@pytest.mark.parametrize("algo,form,arch,history", [
    ("ppo", "residual", (64, 64), 30), ("ppo", "scratch", (2, 3, 4), 10),
    ("sac", "residual", (8,), 30), ("sac", "scratch", (5, 7), 2),
])
def test_the_layout_is_sb3s_state_dict_key_for_key(algo, form, arch, history):
    config = RLConfig(algo=algo, form=form, net_arch=arch, history=history)
    io = PolicyIO.for_env(config, env_action_space())
    policy = build_policy(config, io.observation_space, io.action_space)
    real = {k: tuple(v.shape) for k, v in policy.state_dict().items()}
    assert policy_layout(config) == real
    assert all(v.dtype == torch.float32 for v in policy.state_dict().values())
    assert checkpoint_layout(config)["io.offset"] == (io.offset.shape[0],)
    assert parameter_count(config) == sum(math.prod(s) for s in real.values()) + 2 * len(
        io.offset)


# ---------------------------------------------------------------------- R5: config.json
CRAFTED_CONFIG = {
    "folds-1e9": ("folds", 10**9, r"folds must be in \[2, 100\], got 1000000000"),
    "net-arch-20000": ("net_arch", [20000, 20000], "net_arch must be 1 to 16 positive widths"),
    "net-arch-1e6": ("net_arch", [10**6, 10**6], "net_arch must be 1 to 16 positive widths"),
    "net-arch-deep": ("net_arch", [1] * 40, r"net_arch .*\(1, 1, 1, 1, 1, 1, 1, 1, \.\.\.\)"),
    "net-arch-million": ("net_arch", [1] * 1_000_000,
                         "config field net_arch is a list of 1,000,000 items, more than 1000"),
    "net-arch-params": ("net_arch", [4096, 4096, 4096], "parameters, more than 8,388,608"),
    "history-1e9": ("history", 10**9, r"history must be in \[2, 900\]"),
    "steps-1e30": ("steps", 10**30, r"steps must be in \[1, 10,000,000\]"),
    "n-envs": ("n_envs", 10**9, r"n_envs must be in \[1, 64\]"),
    "lr-1e300": ("learning_rate", 1e300, r"learning_rate must be a finite number in \(0, 1\]"),
    "residual-1e300": ("residual_xyz", 1e300, r"residual_xyz must be a finite number in \(0, 2\]"),
    "batch-size": ("batch_size", 10**12, r"batch_size must be in \[1, 100,000\]"),
    "seed": ("seed", 2**64, r"seed must be in \[0, 4,294,967,295\]"),
}


@pytest.mark.parametrize("case", sorted(CRAFTED_CONFIG))
def test_a_crafted_config_is_refused_quickly_naming_file_and_field(scratch, tmp_path, case):
    field, value, message = CRAFTED_CONFIG[case]
    folder = _copy(scratch, tmp_path / "ckpt")
    edit_config(folder, "config", field, value)
    before = snapshot(tmp_path)
    text = _timed_refusal(folder, message)
    assert text.startswith(f"{folder / 'config.json'}: ") and field in text
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("field,value,message", [
    ("wall_time_s", math.inf, r"training\.wall_time_s must be a finite number of seconds"),
    ("steps", 10**30, r"training\.steps must be a whole number in \[0, 320\]"),
    ("episodes", -1, r"training\.episodes must be a whole number"),
])
def test_a_crafted_training_record_is_refused(scratch, tmp_path, field, value, message):
    folder = _copy(scratch, tmp_path / "ckpt")
    edit_config(folder, "training", field, value)  # json.dumps writes inf as Infinity
    text = _timed_refusal(folder, message)
    assert text.startswith(f"{folder / 'config.json'}: ")


@pytest.mark.parametrize("value", [["x", "y"], [1, 2, 3], 5, [-1, 2], [2**70, 2**70]])
def test_a_crafted_seed_range_is_refused(scratch, tmp_path, value):
    folder = _copy(scratch, tmp_path / "ckpt")
    edit_config(folder, "receivers", "episode_seeds", value)
    text = _timed_refusal(folder, r"receivers\.episode_seeds must be \[\] or two whole seeds")
    assert text.startswith(f"{folder / 'config.json'}: ")


@pytest.mark.parametrize("value", [["a list"], 7, "x" * 5000])
def test_a_crafted_versions_record_is_refused(scratch, tmp_path, value):
    folder = _copy(scratch, tmp_path / "ckpt")
    edit_config(folder, "versions", "commit", value)
    text = _timed_refusal(folder, r"versions\.commit must be a string of at most 4096 characters")
    assert text.startswith(f"{folder / 'config.json'}: ")


# ---------------------------------------------------------------------- R5: the weights file
def _header(folder: Path) -> tuple[int, dict, bytes]:
    raw = (folder / "model.safetensors").read_bytes()
    n = int.from_bytes(raw[:8], "little")
    return n, json.loads(raw[8:8 + n]), raw[8 + n:]


def _write(folder: Path, header: dict, data: bytes, n: int | None = None) -> None:
    text = json.dumps(header).encode()
    size = len(text) if n is None else n
    (folder / "model.safetensors").write_bytes(size.to_bytes(8, "little") + text + data)


def test_an_oversized_weights_file_is_refused_before_it_is_read(scratch, tmp_path):
    """A 4 GiB file (sparse: no disk used) is refused from its size alone, at once."""
    folder = _copy(scratch, tmp_path / "ckpt")
    os.truncate(folder / "model.safetensors", 4 << 30)
    text = _timed_refusal(folder, r"model\.safetensors: 4,294,967,296 bytes, more than the")
    assert "weights file of its config.json (" in text


def test_a_weights_file_a_little_over_its_configs_size_is_refused(scratch, tmp_path):
    folder = _copy(scratch, tmp_path / "ckpt")
    n, header, data = _header(folder)
    _write(folder, header, data + b"\0" * (1 << 20))  # 1 MiB appended
    _timed_refusal(folder, r"model\.safetensors: .* bytes, more than the")


@pytest.mark.parametrize("case,message", [
    ("huge-header-length", r"a header of 18,446,744,073,709,551,615 bytes"),
    ("header-not-json", "header is not JSON"),
    ("wrong-dtype", r"policy\.log_std is 'F64' \[4\], expected torch\.float32 \(4,\)"),
    ("huge-shape", r"is 'F32' \[1000000000, 90\], expected torch\.float32"),
    ("offsets-overlap", "data_offsets .* do not fit its shape|do not tile the data"),
    ("missing-key", r"keys do not match the model \(missing \['policy\.log_std'\]"),
    ("data-short", "bytes of data, its header describes"),
])
def test_a_lying_weights_header_is_refused_before_any_tensor_is_made(scratch, tmp_path, case,
                                                                     message):
    folder = _copy(scratch, tmp_path / "ckpt")
    n, header, data = _header(folder)
    first = next(k for k in header if k.startswith("policy.mlp_extractor") and "weight" in k)
    if case == "huge-header-length":
        _write(folder, header, data, n=2**64 - 1)
    elif case == "header-not-json":
        (folder / "model.safetensors").write_bytes((5).to_bytes(8, "little") + b"{nope" + data)
    elif case == "wrong-dtype":
        header["policy.log_std"]["dtype"] = "F64"
        _write(folder, header, data)
    elif case == "huge-shape":
        header[first]["shape"] = [10**9, 90]
        _write(folder, header, data)
    elif case == "offsets-overlap":
        header["policy.log_std"]["data_offsets"] = [0, 16]
        _write(folder, header, data)
    elif case == "missing-key":
        del header["policy.log_std"]
        _write(folder, header, data)
    else:
        _write(folder, header, data[:-4])
    _timed_refusal(folder, rf"{re.escape(str(folder / 'model.safetensors'))}: .*{message}")


def test_the_largest_admitted_policy_loads_within_bounds(tmp_path):
    """At the parameter bound the load itself (read, check, build, fill) stays small. Measured in
    a fresh process after a tiny checkpoint's load (which pays the imports: torch, SB3, MuJoCo,
    and torch._dynamo on the first optimiser, about 800 MB and several seconds on their own)."""
    import subprocess
    import sys

    def admitted(width: int) -> bool:
        try:
            return parameter_count(RLConfig(form="scratch", net_arch=(width, width))) > 0
        except ValueError:
            return False

    width = next(w for w in range(2048, 0, -8) if admitted(w))
    assert not admitted(width + 8)
    config = RLConfig(form="scratch", net_arch=(width, width))
    assert parameter_count(config) <= MAX_POLICY_PARAMS
    big = write_rl_checkpoint(tmp_path / "big", config)
    tiny = write_rl_checkpoint(tmp_path / "tiny", RLConfig(form="scratch", net_arch=(4,)))
    size = (big / "model.safetensors").stat().st_size
    code = ("import resource, sys, time; import torch; torch.set_num_threads(1); "
            "from baselines.rl.agent import RLAgent; RLAgent.load(sys.argv[2]); "
            "rss = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; r0 = rss(); "
            "t = time.perf_counter(); RLAgent.load(sys.argv[1]); "
            "print(time.perf_counter() - t, r0, rss())")
    proc = subprocess.run([sys.executable, "-c", code, str(big), str(tiny)], capture_output=True,
                          text=True, timeout=600, cwd=Path(__file__).resolve().parents[2])
    assert proc.returncode == 0, proc.stderr[-2000:]
    seconds, before, after = proc.stdout.split()
    grown = (int(after) - int(before)) / 1024
    print(f"net_arch ({width}, {width}): {parameter_count(config):,} values, {size:,} bytes; "
          f"load {float(seconds):.2f} s, peak RSS {int(after) / 1024:.0f} MiB "
          f"(+{grown:.0f} MiB over the imports)")
    assert grown < 512
    assert float(seconds) < 10


def test_closed_loop_refuses_a_crafted_rl_checkpoint_in_one_line(scratch, tmp_path, capsys):
    folder = _copy(scratch, tmp_path / "ckpt")
    edit_config(folder, "config", "folds", 10**9)
    out = tmp_path / "out"
    argv = ["closed-loop", "--quick", "--no-progress", "--agents", "reactive", "rl-scratch",
            "--rl-checkpoint", str(folder), "--out", str(out), "--checkpoints",
            str(tmp_path / "cache")]
    t0 = time.perf_counter()
    assert evaluate.main(argv) == 2
    assert time.perf_counter() - t0 < 30
    err = capsys.readouterr().err.strip()
    assert f"{folder / 'config.json'}: invalid config (folds must be in [2, 100]" in err
    assert "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())


# ---------------------------------------------------------------------- R12: the resume state
def _quick_config() -> RLConfig:
    from handover_eval.cli.rl import config_from_args

    args = train.build_parser().parse_args(QUICK_ARGS + ["--out", "x"])
    return config_from_args(args)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A train.py rl --quick run's folder after its first checkpoint (step 0), written by the
    trainer's own save() without a training step."""
    from baselines.rl.policy import build_model
    from baselines.rl.train import TrainingData, reward_record, save, training_vec_env

    config = _quick_config()
    assert config.steps == QUICK["steps"]
    out = tmp_path_factory.mktemp("rl") / "run"
    vec = training_vec_env(config, make_base(config), TrainingData())
    env = make_handover_env(config)
    try:
        model = build_model(config, vec)
        io = PolicyIO.for_env(config, env.action_space)
        row = {"steps": 0, "success_rate": 0.0, "handover_time": math.nan, "return": -3.5,
               "episodes": 0, "wall_time_s": 1.5}
        state = {"steps": 0, "episodes": [0] * config.n_envs, "curve": [row],
                 "wall_time_s": 1.5}
        save(out, model, io, config, TrainingData(), state, reward_record(config, env))
    finally:
        vec.close()
        env.close()
    return out


def test_the_untampered_state_restores(run_dir):
    from baselines.rl.policy import build_model
    from baselines.rl.train import TrainingData, restore, training_vec_env

    config = _quick_config()
    vec = training_vec_env(config, make_base(config), TrainingData())
    try:
        state = restore(run_dir, build_model(config, vec), config)
    finally:
        vec.close()
    assert state["steps"] == 0 and math.isnan(state["curve"][0]["handover_time"])


def _state_edit(field, value, row: int | None = None):
    def edit(folder: Path) -> None:
        path = folder / "training_state" / "state.json"
        d = json.loads(path.read_text())
        if row is None:
            d[field] = value
        else:
            d["curve"][row][field] = value
        path.write_text(json.dumps(d))
    return edit


TAMPERED_STATE = {
    "steps-1e30": (_state_edit("steps", 10**30),
                   r"state\.json: steps must be a whole number in \[0, 320\]"),
    "wall-infinity": (_state_edit("wall_time_s", math.inf),
                      r"state\.json: wall_time_s must be a finite number of seconds"),
    "episodes-1e30": (_state_edit("episodes", [10**30]),
                      r"state\.json: episodes must be 1 whole counts in \[0, 1,000,000,000\)"),
    "steps-differ": (_state_edit("steps", 64),
                     r"state\.json: steps, episodes or wall_time_s differ from the checkpoint"),
    "curve-return": (_state_edit("return", 1e300, row=0),
                     r"state\.json: curve\[0\]: return must be a finite number"),
    "curve-success": (_state_edit("success_rate", 7.0, row=0),
                      r"state\.json: curve\[0\]: success_rate must be a finite number in \[0, 1\]"),
    "curve-time": (_state_edit("handover_time", -1.0, row=0),
                   r"state\.json: curve\[0\]: handover_time must be NaN"),
    "optimizer-4gib": (lambda f: os.truncate(
        f / "training_state" / "optimizer" / "optimizer_state.safetensors", 4 << 30),
        r"optimizer_state\.safetensors: 4,294,967,296 bytes, more than the .* an optimiser"),
    "lr-1e300": (lambda f: edit_config(f, "config", "learning_rate", 1e300),
                 r"config\.json: invalid config \(learning_rate must be a finite number in"),
    "residual-1e300": (lambda f: edit_config(f, "config", "residual_xyz", 1e300),
                       r"config\.json: invalid config \(residual_xyz must be a finite number"),
}


@pytest.mark.parametrize("case", sorted(TAMPERED_STATE))
def test_a_tampered_resume_state_is_refused_and_nothing_trains(run_dir, tmp_path, case, capsys):
    tamper, message = TAMPERED_STATE[case]
    folder = _copy(run_dir, tmp_path / "run")
    tamper(folder)
    before = snapshot(tmp_path)
    capsys.readouterr()
    assert train.main(QUICK_ARGS + ["--out", str(folder), "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert re.search(message, err), err
    assert err.startswith(f"train.py: error: {folder}") and "\n" not in err
    assert snapshot(tmp_path) == before  # nothing trained, nothing written


def test_train_summary_is_strict_json(tmp_path):
    """A curve point without a success has a NaN handover time: the summary writes null."""
    config = RLConfig(form="scratch", steps=64, n_envs=1)
    row = {"steps": 64, "success_rate": 0.0, "handover_time": math.nan, "return": -1.0,
           "episodes": 2, "wall_time_s": 3.0}
    state = {"steps": 64, "episodes": [2], "curve": [row], "wall_time_s": math.inf}
    write_summary(tmp_path, state, config, {"seed": 0})

    def refuse(name: str):
        raise ValueError(f"{name} in train_summary.json")

    body = json.loads((tmp_path / "train_summary.json").read_text(), parse_constant=refuse)
    assert body["end"]["handover_time"] is None and body["wall_time_s"] is None
    assert body["end"]["return"] == -1.0


# ---------------------------------------------------------------------- issue 36: new forms
#: The policy forms the levers make, each a different state dict (gSDE's log std, the
#: privileged critic's wider input, the remembered actions' wider observation).
NEW_FORMS = {
    "ppo-sde-privileged": dict(algo="ppo", use_sde=True, privileged_critic=True, last_actions=2,
                               action_tau=0.1, base="cv"),
    "sac-sde-privileged": dict(algo="sac", form="scratch", use_sde=True, privileged_critic=True,
                               action_noise="pink", last_actions=1),
    "sac-warm-start": dict(algo="sac", form="scratch", warm_start="cv", warm_start_episodes=3),
}


@pytest.mark.parametrize("form", sorted(NEW_FORMS))
def test_the_layout_of_each_new_form_is_sb3s_state_dict_key_for_key(form):
    config = RLConfig(net_arch=(8, 6), **NEW_FORMS[form])
    io = PolicyIO.for_env(config, env_action_space())
    policy = build_policy(config, training_observation_space(config, io), io.action_space)
    assert policy_layout(config) == {k: tuple(v.shape) for k, v in policy.state_dict().items()}


@pytest.fixture(scope="module")
def new_forms(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("forms")
    out = {name: write_rl_checkpoint(root / name, RLConfig(net_arch=(8,), steps=256, n_envs=1,
                                                           n_steps=64, **kw))
           for name, kw in NEW_FORMS.items()}
    for name, folder in out.items():  # untampered, each loads
        assert RLAgent.load(folder).config.algo == NEW_FORMS[name]["algo"]
    return out


def _pickled_weights(folder: Path) -> None:
    import pickle

    from planted import PAYLOAD

    class Boom:
        def __reduce__(self):
            return (exec, (PAYLOAD,))

    (folder / "model.safetensors").write_bytes(pickle.dumps(Boom()))


def _narrower_critic(folder: Path) -> None:
    """The weights of the same config without the privileged critic (a critic input 18 short)."""
    d = json.loads((folder / "config.json").read_text())
    d["config"]["privileged_critic"] = False
    config = RLConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in d["config"].items()})
    other = folder.parent / (folder.name + "-plain")
    write_rl_checkpoint(other, config)
    (folder / "model.safetensors").write_bytes((other / "model.safetensors").read_bytes())


NEW_FORM_TAMPERING = {
    "use-sde-string": (lambda f: edit_config(f, "config", "use_sde", "yes"),
                       "config field use_sde = 'yes' is not a bool"),
    "privileged-int": (lambda f: edit_config(f, "config", "privileged_critic", 1),
                       "config field privileged_critic = 1 is not a bool"),
    "action-tau-huge": (lambda f: edit_config(f, "config", "action_tau", 1e300),
                        r"action_tau must be a finite number in \[0, 10\]"),
    "last-actions-1e9": (lambda f: edit_config(f, "config", "last_actions", 10**9),
                         r"last_actions must be in \[0, 30\]"),
    "noise-unknown": (lambda f: edit_config(f, "config", "action_noise", "os.system"),
                      "action_noise must be one of"),
    "sde-off": (lambda f: edit_config(f, "config", "use_sde", False),
                "keys do not match the model|expected torch.float32"),
    "reward-weight": (lambda f: edit_config(f, "reward", "contact_penalty", 5.0),
                      "disagree with its config"),
    "narrower-critic": (_narrower_critic, "bytes, more than the|expected torch.float32|"
                        "keys do not match"),
    "pickle-as-weights": (_pickled_weights, "not a readable safetensors file|bytes, more than"),
}


@pytest.mark.parametrize("form", sorted(NEW_FORMS))
@pytest.mark.parametrize("case", sorted(NEW_FORM_TAMPERING))
def test_a_tampered_checkpoint_of_each_new_form_is_one_named_error_and_runs_nothing(
        new_forms, tmp_path, form, case):
    tamper, message = NEW_FORM_TAMPERING[case]
    if case == "narrower-critic" and not NEW_FORMS[form].get("privileged_critic"):
        pytest.skip("no privileged critic in this form")
    if case == "sde-off" and not NEW_FORMS[form].get("use_sde"):
        pytest.skip("no gSDE in this form")
    folder = _copy(new_forms[form], tmp_path / "ckpt")
    tamper(folder)
    before = snapshot(tmp_path)
    cwd = os.getcwd()
    os.chdir(tmp_path)  # the payload would write MARKER here
    try:
        _timed_refusal(folder, message)
    finally:
        os.chdir(cwd)
    assert not (tmp_path / "MARKER").exists()
    assert snapshot(tmp_path) == before
