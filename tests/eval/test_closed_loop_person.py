"""evaluate.py closed-loop --person: the opt-in person settings reach the env of every episode."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import gymnasium as gym
import pytest

import evaluate
import handover_env  # noqa: F401  (registers the envs)
from handover_eval.closedloop.run import ClosedLoopEvalConfig


def _rows(path: Path) -> list[dict]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def _run(tmp_path: Path, name: str, *person: str) -> list[dict]:
    argv = ["closed-loop", "--quick", "--no-progress", "--workers", "1", "--agents", "reactive",
            "--sets", "id", "--walkers", "3", "--out", str(tmp_path / name),
            "--checkpoints", str(tmp_path / "checkpoints")]
    if person:
        argv += ["--person", *person]
    assert evaluate.main(argv) == 0
    return _rows(tmp_path / name / "closed_loop_episodes.csv")


def test_person_settings_reach_every_episode_and_default_stays_default(tmp_path: Path) -> None:
    default = _run(tmp_path, "default")
    plain = _run(tmp_path, "plain", "reach_offset=off")
    assert [r["receiver"] for r in default] == [r["receiver"] for r in plain]
    # switched off the person has no reach offset; by default each walker draws its own, the
    # same as gym.make(...) with that walker's seed
    assert all(float(r["reach_offset"]) == 0.0 for r in plain)
    env = gym.make("handover_env/DynamicHandover-v0")
    for row in default:
        _, info = env.reset(seed=int(row["seed"]), options={"receiver": "id"})
        # the CSV keeps 7 significant digits
        assert float(row["reach_offset"]) == pytest.approx(info["reach_offset"], abs=1e-6)
    env.close()
    assert any(abs(float(r["reach_offset"])) > 1e-3 for r in default)
    header = (tmp_path / "plain" / "closed_loop.md").read_text()
    assert "person switches `reach_offset=off`" in header
    assert "the default person" in (tmp_path / "default" / "closed_loop.md").read_text()


def test_env_kwargs_carry_the_person_only_when_set() -> None:
    assert json.loads(ClosedLoopEvalConfig(agents=("reactive",)).env_kwargs()) == {
        "sensing": "paper"}
    cfg = ClosedLoopEvalConfig(agents=("reactive",), person=("arm_yield=off", "reach_offset"))
    assert json.loads(cfg.env_kwargs(sensors={"x": 1})) == {
        "sensing": "paper", "sensors": {"x": 1},
        "person": {"arm_yield": False, "reach_offset": True}}
    cfg = ClosedLoopEvalConfig(agents=("reactive",), person=("avoid_gripper=on",))
    assert json.loads(cfg.env_kwargs())["person"] == {"avoid_gripper": True}


@pytest.mark.parametrize("person", [("tall",), ("arm_yield", "arm_yield"),
                                    ("arm_yield", "arm_yield=off"), ("arm_yield=maybe",)])
def test_unknown_or_repeated_person_setting_is_refused(person: tuple[str, ...]) -> None:
    with pytest.raises(ValueError, match="--person"):
        ClosedLoopEvalConfig(agents=("reactive",), person=person)


def test_cli_refuses_an_unknown_setting(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        evaluate.main(["closed-loop", "--person", "tall"])
    err = capsys.readouterr().err
    assert "--person" in err and "'tall'" in err and "NAME=off" in err
