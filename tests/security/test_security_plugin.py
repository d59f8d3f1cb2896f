"""Issue 32, R10 and R16: a plug-in agent cannot hang the benchmark or end it silently, and its
``--agent-config`` holds finite numbers only.

The guard itself (:mod:`handover_eval.benchmark.guard`) is checked directly (a blocking call, one
that swallows ``Exception``, ``SystemExit(0)``, ``KeyboardInterrupt``, the handler and timer
restored); then ``evaluate.py benchmark --quick`` runs plug-ins written here that block in
``act()`` (in this process) and in ``predict()`` (in two worker processes), exit with status 0
from ``act()``, exit with status 3 at import, or raise ``KeyboardInterrupt``: each run ends in one
line naming the agent (and the episode), with a nonzero status, within a time bound, and writes
no result.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import evaluate  # noqa: E402
from handover_eval.benchmark.guard import (  # noqa: E402
    AgentError,
    AgentInterrupted,
    agent_guard,
    forget_stopped,
)
from handover_eval.benchmark.plugin import parse_config, resolve  # noqa: E402

PLUGIN = '''
import sys, time
import numpy as np
from agents.predictive import PredictiveAgent


class Misbehaving(PredictiveAgent):
    def __init__(self, mode):
        super().__init__()
        self.mode, self.horizon = mode, 30

    def predict(self, receiver_history):
        if self.mode == "block-predict":
            time.sleep(3600)
        return np.tile([0.4, float(receiver_history[-1][1]), 1.0], (self.horizon, 1))

    def act(self, obs):
        if self.mode == "block-act":
            while True:  # swallows Exception: the guard's alarm is a BaseException
                try:
                    time.sleep(3600)
                except Exception:
                    pass
        if self.mode == "exit-0":
            sys.exit(0)
        if self.mode == "interrupt":
            raise KeyboardInterrupt
        return super().act(obs)


def make(mode="ok"):
    return Misbehaving(mode)
'''


# ---------------------------------------------------------------------- the guard
@pytest.fixture(autouse=True)
def _fresh():
    forget_stopped()
    yield
    forget_stopped()


def test_a_blocking_call_is_stopped_at_the_limit_naming_agent_and_episode():
    t0 = time.perf_counter()
    with pytest.raises(AgentError, match=r"agent 'slow': episode id/walker-3 ran past the "
                       r"per-episode time limit of 0\.3 s \(--episode-time-limit\)"):
        with agent_guard("slow", "episode id/walker-3", 0.3, key=("run", "slow")):
            time.sleep(30)
    assert time.perf_counter() - t0 < 3
    # the same agent's next episode in this process fails at once, another agent's runs
    t0 = time.perf_counter()
    with pytest.raises(AgentError, match="agent 'slow': episode id/walker-3 ran past"):
        with agent_guard("slow", "episode id/walker-4", 0.3, key=("run", "slow")):
            time.sleep(30)
    assert time.perf_counter() - t0 < 0.2
    with agent_guard("other", "episode id/walker-4", 5.0, key=("run", "other")):
        done = True
    assert done


def test_an_agent_that_swallows_exceptions_is_still_stopped():
    t0 = time.perf_counter()
    with pytest.raises(AgentError, match=r"agent 'stubborn': act\(\) ran past"):
        with agent_guard("stubborn", "act()", 0.3):
            while True:
                try:
                    time.sleep(30)
                except Exception:  # noqa: BLE001 - what a careless plug-in does
                    pass
    assert time.perf_counter() - t0 < 3


def test_the_alarm_is_disarmed_and_the_handler_restored():
    previous = signal.getsignal(signal.SIGALRM)
    with agent_guard("quick", "episode", 0.2):
        pass
    assert signal.getsignal(signal.SIGALRM) is previous
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    time.sleep(0.5)  # no late alarm
    with pytest.raises(AgentError, match="raised SystemExit"):
        with agent_guard("quick", "episode", 0.2):
            raise SystemExit(0)
    assert signal.getsignal(signal.SIGALRM) is previous
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


@pytest.mark.parametrize("code,shown", [(0, "0"), (3, "3"), (None, "None"), ("bye", "'bye'")])
def test_system_exit_in_the_agents_code_is_an_error_naming_the_agent(code, shown):
    with pytest.raises(AgentError, match=rf"agent 'quitter': act\(\) raised SystemExit\({shown}\); "
                       "an agent may not end the benchmark"):
        with agent_guard("quitter", "act()", 10.0):
            raise SystemExit(code)


def test_keyboard_interrupt_in_the_agents_code_names_it():
    with pytest.raises(AgentInterrupted, match="agent 'ctrl': interrupted during episode 7"):
        with agent_guard("ctrl", "episode 7", 10.0):
            raise KeyboardInterrupt


def test_no_alarm_is_armed_outside_the_main_thread():
    seen = []

    def body() -> None:
        with agent_guard("threaded", "episode", 0.05):
            time.sleep(0.3)
        seen.append(signal.getitimer(signal.ITIMER_REAL))

    t = threading.Thread(target=body)
    t.start()
    t.join()
    assert seen == [(0.0, 0.0)]


# ---------------------------------------------------------------------- R16: --agent-config
@pytest.mark.parametrize("text,message", [
    ('{"k": 1e999}', r"--agent-config: k is inf \(a number too large for a float\)"),
    ('{"k": -1e999}', r"--agent-config: k is -inf"),
    ('{"a": [1, {"b": 1e400}]}', r"--agent-config: a\[1\]\.b is inf"),
    ('{"k": NaN}', "--agent-config: NaN is not allowed"),
    ('{"k": Infinity}', "--agent-config: Infinity is not allowed"),
    ('{"k": ' + "[" * 3000 + "]" * 3000 + "}", "--agent-config is nested too deeply"),
    ('{"k\\n": 1}', "--agent-config keys must be Python identifiers"),
])
def test_agent_config_refuses_numbers_that_are_not_finite(text, message):
    with pytest.raises(ValueError, match=message):
        parse_config(text)
    assert parse_config('{"k": 1e300, "j": [1, 2.5]}') == '{"j": [1, 2.5], "k": 1e+300}'


@pytest.mark.parametrize("value", [0, -1.0, float("inf"), float("nan"), 86_401, True])
def test_resolve_checks_the_episode_limit(tmp_path, value):
    (tmp_path / "p.py").write_text(PLUGIN)
    with pytest.raises(ValueError, match=r"--episode-time-limit must be a number of seconds in "
                       r"\(0, 86400\]"):
        resolve(f"{tmp_path / 'p.py'}:make", episode_limit_s=value)


@pytest.mark.parametrize("value", ["0", "-5", "inf", "nan", "1e9", "soon"])
def test_the_episode_limit_flag_is_validated(tmp_path, value, capsys):
    with pytest.raises(SystemExit, match="2"):
        evaluate.main(["benchmark", "--agent", "reactive", "--episode-time-limit", value,
                       "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert "argument --episode-time-limit" in err and not (tmp_path / "out").exists()


# ---------------------------------------------------------------------- end to end
def _bench(tmp_path: Path, mode: str, *extra: str) -> tuple[int, float]:
    plugin = tmp_path / "plugins" / "misbehaving.py"
    plugin.parent.mkdir(exist_ok=True)
    plugin.write_text(PLUGIN)
    argv = ["benchmark", "--agent", f"{plugin}:make", "--name", "rogue", "--agent-config",
            f'{{"mode": "{mode}"}}', "--quick", "--no-progress", "--out", str(tmp_path / "out"),
            "--checkpoints", str(tmp_path / "ckpt"), *extra]
    t0 = time.perf_counter()
    status = evaluate.main(argv)
    return status, time.perf_counter() - t0


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "Traceback" not in err[0]
    return err[0]


def _no_result(tmp_path: Path) -> None:
    assert {p.name for p in tmp_path.iterdir()} <= {"ckpt", "out", "plugins"}
    assert not (tmp_path / "out" / "result.json").exists()


def test_a_plugin_blocking_in_act_is_stopped_in_this_process(tmp_path, capsys):
    status, seconds = _bench(tmp_path, "block-act", "--tracks", "closedloop", "--workers", "1",
                             "--episode-time-limit", "2")
    line = _one_line(capsys)
    assert status == 1, line
    assert "agent 'rogue': closed-loop episode " in line
    assert "ran past the per-episode time limit of 2 s (--episode-time-limit)" in line
    assert seconds < 240
    _no_result(tmp_path)


def test_a_plugin_blocking_in_predict_is_stopped_in_the_worker_processes(tmp_path, capsys):
    status, seconds = _bench(tmp_path, "block-predict", "--tracks", "openloop", "--workers", "2",
                             "--episode-time-limit", "2")
    line = _one_line(capsys)
    assert status == 1, line
    assert "open-loop track" in line and "agent 'rogue': open-loop episode " in line
    assert "ran past the per-episode time limit of 2 s" in line
    assert seconds < 300
    _no_result(tmp_path)


def test_sys_exit_0_in_act_is_an_error_not_a_silent_success(tmp_path, capsys):
    status, _ = _bench(tmp_path, "exit-0", "--tracks", "closedloop", "--workers", "1")
    line = _one_line(capsys)
    assert status == 1, line
    assert "agent 'rogue': closed-loop episode " in line and "raised SystemExit(0)" in line
    _no_result(tmp_path)


def test_keyboard_interrupt_in_act_is_a_clean_stop(tmp_path, capsys):
    status, _ = _bench(tmp_path, "interrupt", "--tracks", "closedloop", "--workers", "1")
    line = _one_line(capsys)
    assert status == 130, line
    assert line.startswith("evaluate.py: interrupted: agent 'rogue': interrupted during "
                           "closed-loop episode ")
    _no_result(tmp_path)


def test_a_plugin_exiting_at_import_is_an_error_naming_it(tmp_path, capsys):
    plugin = tmp_path / "plugins" / "quits.py"
    plugin.parent.mkdir()
    plugin.write_text("raise SystemExit(3)\n")
    status = evaluate.main(["benchmark", "--agent", f"{plugin}:make", "--quick", "--no-progress",
                            "--out", str(tmp_path / "out"), "--checkpoints",
                            str(tmp_path / "ckpt")])
    line = _one_line(capsys)
    assert status == 1, line
    assert f"agent 'quits:make': importing {plugin} raised SystemExit(3)" in line
    _no_result(tmp_path)
