"""CoSpar on the env (handover_eval/preference.py), train.py preference and the check."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from agents.cospar import CoSparConfig, action_grid
from agents.participants import sample_participant, sample_population
from handover_eval.preference.tuning import (
    EpisodeRunner,
    PreferenceConfig,
    lived,
    run_preference,
    summarise_outcomes,
)

SMALL = CoSparConfig(points_per_dim=(3, 3, 3, 3))


def _judge_towards(target: np.ndarray):
    grid = action_grid(SMALL)
    span = grid.max(axis=0) - grid.min(axis=0)
    return lambda p, a: float(-np.sum(((grid[a] - target) / span) ** 2) * 4.0)


def test_pooled_participants_share_one_posterior_and_find_a_common_optimum() -> None:
    people = sample_population(3, seed=5)
    target = action_grid(SMALL)[40]
    result = run_preference(
        people, PreferenceConfig(iterations=8, cospar=SMALL, seed=1), judge=_judge_towards(target)
    )
    assert {r["participant"] for r in result.preferences} == {p.pid for p in people}
    assert len(result.history) >= 8 * 3 * SMALL.n_samples
    assert np.allclose(result.theta_hat.as_array(), target)
    # one learner: every participant's answers are in its data
    assert len(result.learner.preferences) == len(result.preferences)


def test_run_is_deterministic_under_its_seeds() -> None:
    runs = []
    for _ in range(2):
        p = sample_participant(4)
        r = run_preference([p], PreferenceConfig(iterations=4, cospar=SMALL, seed=2),
                           judge=_judge_towards(action_grid(SMALL)[7]))
        runs.append((r.theta_hat, [(x["winner_index"], x["loser_index"]) for x in r.preferences]))
    assert runs[0] == runs[1]


def test_summary_of_outcomes() -> None:
    infos = [{"outcome": "success", "handover_time": 2.0, "pull_force": 10.0, "release_force": 6.0},
             {"outcome": "missed", "handover_time": None, "pull_force": 0.0, "release_force": None}]
    s = summarise_outcomes(infos)
    assert s["success_rate"] == 0.5 and s["handover_time"] == 2.0 and s["pull_force"] == 5.0
    assert s["measured_release_force"] == 6.0 and "release_force" not in s
    # a numerical blow-up is not a lived handover: not judged, unless nothing else is left
    unstable = {"outcome": "unstable"}
    assert lived([infos[0], unstable]) == [infos[0]] and lived([unstable]) == [unstable]
    assert summarise_outcomes([infos[0], unstable])["unstable"] == 1.0


def test_runner_caches_episodes_and_runs_static_too() -> None:
    from handover_env.config import HandoverParams

    runner = EpisodeRunner("reactive", "id")
    p = sample_participant(2)
    theta = HandoverParams(110.0, 15.0, 0.3, 8.0)
    seeds = p.walk_seeds(1)
    a = runner.run(p, theta, seeds)
    assert (
        runner.episodes_run == 1 and runner.run(p, theta, seeds) == a and runner.episodes_run == 1
    )
    s = runner.run(p, theta, seeds, static=True)
    assert runner.episodes_run == 2
    # the reactive robot hands the object over to this walker (paper profile, seeded walk)
    assert a[0]["outcome"] == "success"
    assert a[0]["handover_time"] == a[0]["release_time"] == a[0]["handover_time_with_delay"] > 0
    assert a[0]["pull_force"] > 0 and a[0]["release_force"] > theta.release_force
    # the static robot waits for the raised hand; the paper wrist's noise (3.5 N precision)
    # crosses this Theta's f_r = 8 N before anyone pulls: a premature release, nobody held it
    assert s[0]["outcome"] == "premature_release"
    assert s[0]["handover_time"] is None and s[0]["handover_time_with_delay"] is None
    assert s[0]["pull_force"] == 0.0 and s[0]["release_force"] > theta.release_force
    assert s[0]["release_time"] > 2.0  # after the static task's 2 s stabilisation at least
    runner.close()


def test_runner_runs_the_chosen_sensing_profile_and_refuses_others(tmp_path: Path) -> None:
    from handover_env.config import HandoverParams
    from handover_eval.preference.check import load_episode_cache, save_episode_cache

    with pytest.raises(ValueError, match="sensing must be one of"):
        EpisodeRunner("reactive", "id", sensing="perfect")
    p = sample_participant(2)
    theta = HandoverParams(110.0, 15.0, 0.3, 8.0)
    seeds = p.walk_seeds(1)
    infos = {}
    for sensing in ("ideal", "paper"):
        runner = EpisodeRunner("reactive", "id", sensing=sensing)
        infos[sensing] = runner.run(p, theta, seeds)[0]
        assert runner.env(theta).unwrapped.sensing == sensing
        if sensing == "ideal":
            save_episode_cache(runner, tmp_path / "episodes.jsonl")
        runner.close()
    # the two worlds differ (the paper's camera and F/T), and the default is the env's: paper
    assert infos["ideal"] != infos["paper"] and EpisodeRunner("reactive").sensing == "paper"
    # the brute-force check's episode cache never serves an episode of another profile
    paper, ideal = EpisodeRunner("reactive", "id"), EpisodeRunner("reactive", "id", sensing="ideal")
    load_episode_cache(paper, tmp_path / "episodes.jsonl")
    load_episode_cache(ideal, tmp_path / "episodes.jsonl")
    assert len(paper.cache) == 0 and len(ideal.cache) == 1


def test_train_preference_cli_writes_theta_history_and_plot(tmp_path: Path, capsys) -> None:
    from handover_eval.cli import train

    out = tmp_path / "run"
    code = train.main(["preference", "--participant", "3", "--iterations", "2", "--walks", "1",
                       "--grid", "2,2,2,2", "--out", str(out), "--no-progress"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "Θ̂" in printed and "114.3" in printed  # ours beside the paper's
    record = json.loads((out / "theta_hat.json").read_text())
    assert set(record["theta_hat"]) == {"stiffness", "damping", "forecast_time", "release_force"}
    assert "simulated" in record["source"] and record["episodes"] >= 2
    rows = list(csv.DictReader((out / "history.csv").open()))
    assert rows and {
        "iteration",
        "stiffness",
        "success_rate",
        "hidden_utility",
        "comparisons_won",
    } <= set(rows[0])
    assert (out / "posterior_marginals.png").stat().st_size > 1000
    assert list(csv.DictReader((out / "preferences.csv").open()))


@pytest.mark.parametrize(
    "argv",
    [
        ["--grid", "1,2,2,2"],
        ["--participant", "-1"],
        ["--iterations", "0"],
        ["--participant", "1", "--participants", "2"],
    ],
)
def test_train_preference_rejects_bad_input(argv: list[str], capsys) -> None:
    from handover_eval.cli import train

    with pytest.raises(SystemExit, match="^2$") as exc:
        train.main(["preference", *argv])
    assert exc.value.code == 2
    assert "error" in capsys.readouterr().err


def test_brute_force_check_scores_cospar_against_the_grid_optimum(tmp_path: Path) -> None:
    from handover_eval.preference.check import CheckConfig, run_check

    class FakeRunner(EpisodeRunner):
        """Outcomes that depend on Θ (pull grows with f_r, failures at t_f = 1) without physics."""

        def run(self, participant, theta, seeds, static=False):
            k, b, tf, fr = theta.as_array()
            ok = tf < 0.9
            self.episodes_run += len(seeds)
            return [
                {
                    "outcome": "success" if ok else "missed",
                    "handover_time": 2.0 + tf,
                    "handover_time_with_delay": 2.0 + tf,
                    "pull_force": 2.0 * fr,
                    "reach_distance": 0.5,
                    "arm_extended_time": 1.0,
                    "robot_jerk_rms": k / 3.0 + b,
                    "body_contact_force": 0.0,
                    "time_lost": 0.0,
                }
                for _ in seeds
            ]

    rows = run_check(
        CheckConfig(participants=2, grid=(2, 2, 3, 3), walks=1, iterations=6),
        tmp_path,
        progress=False,
        runner=FakeRunner(),
    )
    assert len(rows) == 2 and all(0.0 <= r["gain"] <= 1.0 for r in rows)
    assert all(r["best_forecast_time"] < 0.9 and r["best_release_force"] == 5.0 for r in rows)
    assert (tmp_path / "check.md").read_text().count("| yes |") + (
        tmp_path / "check.md"
    ).read_text().count("| no |") == 2
