"""Issue 20 item 9: every integer count option of train.py and evaluate.py has a stated maximum.

A count beyond it (``--iterations 99999999999999999999`` used to run for ever) ends in one error
naming the option and its range, before anything runs or is written.
"""

from __future__ import annotations

import argparse
import re

import pytest

from handover_eval.cli import closedloop as cli_closedloop
from handover_eval.cli import evaluate as evaluate_cli
from handover_eval.cli import train as train_cli
from handover_eval.cli.args import IntRange, int_in_range

HUGE = "99999999999999999999"


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_int_in_range_parses_bounds_and_names_them() -> None:
    walks = int_in_range(1, 1000)
    assert walks("1") == 1 and walks("1000") == 1000
    for text, message in [("0", "must be an integer in [1, 1000], got 0"),
                          ("1001", "must be an integer in [1, 1000], got 1001"),
                          ("2.5", "expected a whole number, got '2.5'"),
                          ("9" * 5000, "expected a whole number")]:
        with pytest.raises(argparse.ArgumentTypeError, match=re.escape(message)):
            walks(text)
    with pytest.raises(ValueError, match=r"^--walks must be an integer in \[1, 1000\], got 0$"):
        walks.check("--walks", [3, 0])
    walks.check("--walks", None)  # unset
    with pytest.raises(ValueError, match=r"empty range \[5, 1\]"):
        int_in_range(5, 1)


def test_every_integer_option_is_bounded() -> None:
    """No plain ``type=int`` is left unchecked: each is an IntRange, or (evaluate.py's open- and
    closed-loop commands, whose bad values are one-line errors of the command) in COUNTS."""
    checked_later = {"table1": evaluate_cli.COUNTS, "sample-efficiency": evaluate_cli.COUNTS,
                     "tradeoff": evaluate_cli.COUNTS, "closed-loop": cli_closedloop.COUNTS,
                     "theta-sweep": cli_closedloop.COUNTS, "sensing-sweep": cli_closedloop.COUNTS}
    seen = 0
    for parser in (train_cli.build_parser(), evaluate_cli.build_parser()):
        for name, sub in _subcommands(parser).items():
            for action in sub._actions:
                if action.type is int:
                    flag = action.option_strings[0]
                    assert flag in checked_later.get(name, {}), f"{name} {flag} is unbounded"
                    seen += 1
                elif isinstance(action.type, IntRange):
                    seen += 1
    assert seen > 50


@pytest.mark.parametrize(
    "argv",
    [
        ["preference", "--iterations", HUGE],
        ["preference", "--participants", HUGE],
        ["preference", "--walks", HUGE],
        ["preference", "--seed", HUGE],
        ["preference", "--grid", f"7,6,6,{HUGE}"],
        ["preference-check", "--participants", HUGE],
        ["preference-check", "--iterations", "10001"],
        ["bc-mlp", "--smoke", "--out", "o", "--epochs", HUGE],
        ["bc-mlp", "--smoke", "--out", "o", "--threads", "257"],
        ["bc-mlp", "--smoke", "--out", "o", "--hidden", "64", HUGE],
        ["act", "--smoke", "--out", "o", "--steps", HUGE],
        ["act", "--smoke", "--out", "o", "--folds", "101"],
    ],
)
def test_train_counts_beyond_their_maximum_are_argparse_errors(argv, tmp_path, monkeypatch,
                                                               capsys) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match="^2$") as exc:
        train_cli.main(argv)
    assert exc.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    flag = [a for a in argv if a.startswith("--")][-1]
    assert last.startswith(f"train.py {argv[0]}: error: argument {flag}: ")
    assert "must be" in last or "expected 4" in last
    assert "[" in last  # the range is stated
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "argv",
    [
        ["user-study", "--participants", HUGE],
        ["user-study", "--trials", HUGE],
        ["user-study", "--workers", "257"],
    ],
)
def test_user_study_counts_are_argparse_errors(argv, tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match="^2$") as exc:
        evaluate_cli.main(argv)
    assert exc.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"error: argument {argv[-2]}: must be an integer in [" in last
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["closed-loop", "--walkers", HUGE],
         f"--walkers must be an integer in [1, 10000], got {HUGE}"),
        (["closed-loop", "--bootstrap", "0"],
         "--bootstrap must be an integer in [1, 1000000], got 0"),
        (["closed-loop", "--replay-folds", "5", HUGE],
         "--replay-folds must be an integer in [0, 99]"),
        (["theta-sweep", "--values", HUGE], "--values must be an integer in [2, 101]"),
        (["table1", "--workers", "1000"], "--workers must be an integer in [1, 256], got 1000"),
        (["table1", "--act-steps", HUGE], "--act-steps must be an integer in [1, 10000000]"),
        (["sample-efficiency", "--folds", "1"], "--folds must be an integer in [2, 100], got 1"),
        (["tradeoff", "--timing-episodes", HUGE], "--timing-episodes must be an integer in [1, "),
        (["table1", "--seed", "-1"], "--seed must be an integer in [0, 4294967295], got -1"),
    ],
)
def test_evaluate_counts_beyond_their_range_are_one_line_errors(argv, message, tmp_path,
                                                                monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    assert evaluate_cli.main([*argv, "--quick", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"evaluate.py: error: {message}") and "\n" not in err, err
    assert list(tmp_path.iterdir()) == []  # refused before any folder is made
