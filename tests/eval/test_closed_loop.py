"""evaluate.py closed-loop and theta-sweep: the quick runs, fold models per replay, worker
independence, the episode rows, and clean errors on bad input."""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import evaluate
from handover_env.config import HandoverParams
from handover_env.person.synthetic import generate_synthetic
from handover_eval.closedloop.report import GROUPS, groups_of
from handover_eval.closedloop.run import ClosedLoopEvalConfig, plan_jobs
from handover_eval.closedloop.worker import EpisodeJob
from handover_eval.episodes import episode_row
from handover_eval.methods import MethodOptions
from handover_eval.receivers import (
    ReceiverSpec,
    fold_of,
    pick_evenly,
    replays,
    walkers,
)
from handover_eval.roster import compared_agents

DATA = (
    Path(__file__).resolve().parents[2].parent
    / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"
)


def _rows(path: Path) -> list[dict]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def quick_run(closed_loop_every_agent: Path) -> Path:
    """The --quick closed-loop run with every agent on the ideal sensing profile, the exact world
    these tests were written for (issue 24): the session's shared run (tests/conftest.py)."""
    return closed_loop_every_agent / "out"


def test_quick_closed_loop_runs_every_agent_on_the_same_receivers(quick_run: Path) -> None:
    rows = _rows(quick_run / "closed_loop_episodes.csv")
    receivers = {(r["set"], r["receiver"]) for r in rows}
    assert {s for s, _ in receivers} == {"id", "ood", "replay"}
    assert len(receivers) == 2 + 2 + 3  # --quick: 2 walkers per set, 3 replays of fold 0
    for agent in compared_agents():
        mine = {(r["set"], r["receiver"]) for r in rows if r["agent"] == agent}
        expected = (
            {k for k in receivers if k[0] == "replay"} if agent == "giver-replay" else receivers
        )
        assert mine == expected, agent
    for r in rows:
        assert r["env"] == ("static" if r["agent"] == "static" else "dynamic")
        assert r["outcome"] in ("success", "premature_release", "dropped", "unsafe_force", "missed",
                                "unstable", "timeout")
        assert (r["outcome"] == "success") == (r["is_success"] == "True")
        if r["outcome"] == "success":  # the paper's handover time exists exactly for successes
            assert float(r["handover_time"]) > 0 and r["release_before_grasp"] == "False"
            assert float(r["transfer_time"]) <= float(r["release_time"])
        else:
            assert math.isnan(float(r["handover_time"]))
        if r["agent"] in (
            "ours",
            "iaal",
            "bc-mlp",
            "act",
        ):  # fold models: fold 0 for everything here
            assert r["model_fold"] == "0"
        else:
            assert r["model_fold"] == ""
        assert (float(r["K"]), float(r["B"]), float(r["t_f"]), float(r["f_r"])) == (
            114.3,
            17.1,
            0.14,
            7.1,
        )
        assert (r["body_contact"] == "True") == (float(r["body_contact_force"]) > 0)
        assert int(r["steps"]) >= 1 and int(r["sim_unstable"]) >= 0
    agg = _rows(quick_run / "closed_loop.csv")
    assert {a["set"] for a in agg} <= set(GROUPS) and {"walker-id", "walker-ood", "replay-all"} <= {
        a["set"] for a in agg
    }
    n_ood = sum(r["is_ood"] == "True" for r in rows if r["set"] == "replay")
    assert ("replay-ood" in {a["set"] for a in agg}) == (n_ood > 0)
    for a in agg:  # the table's success rate is the episodes' one, per receiver group
        mine = [r for r in rows if r["agent"] == a["agent"] and a["set"] in groups_of(r)]
        assert int(a["n"]) == len(mine)
        assert float(a["success_rate"]) == pytest.approx(
            sum(r["outcome"] == "success" for r in mine) / len(mine))
        assert float(a["success_low"]) <= float(a["success_rate"]) <= float(a["success_high"])
    pairs = _rows(quick_run / "closed_loop_paired.csv")
    assert {p["agent"] for p in pairs} == set(compared_agents()) - {"reactive"}
    assert {p["metric"] for p in pairs} >= {
        "success",
        "handover_time",
        "time_lost",
        "arm_extended_time",
        "reach_distance",
        "pull_force",
        "body_contact_force",
        "body_contact",
        "robot_jerk_rms",
    }
    for p in pairs:
        if int(p["n_pairs"]):
            assert float(p["diff_low"]) <= float(p["diff"]) <= float(p["diff_high"])
            assert float(p["mean_low"]) <= float(p["mean_diff"]) <= float(p["mean_high"])
    md = (quick_run / "closed_loop.md").read_text()
    assert "simulated person" in md and "No ghosts" in md and "start of the recording" in md
    assert "Paired against the reactive agent" in md
    assert "Sensing profile `ideal`" in md  # the header names the world it was measured in
    assert (quick_run / "closed_loop.png").stat().st_size > 20_000
    ghosts = _rows(quick_run / "closed_loop_ghosts.csv")
    assert (ghosts[0]["agent"], ghosts[0]["set"]) == ("all", "all")
    assert int(ghosts[0]["n"]) == len(rows)
    by_set = {g["set"]: int(g["n"]) for g in ghosts if g["agent"] == "all"}
    assert by_set["walker-id"] == sum(r["set"] == "id" for r in rows)
    assert by_set["replay-all"] == sum(r["set"] == "replay" for r in rows)
    for group in ("walker-id", "walker-ood", "replay-all"):
        assert f"| {group} |" in md
    assert int(ghosts[0]["episodes_sim_unstable"]) == sum(int(r["sim_unstable"]) > 0 for r in rows)
    assert int(ghosts[0]["successes_release_before_grasp"]) == 0
    timing = _rows(quick_run / "closed_loop_timing.csv")
    assert sum(int(t["episodes"]) for t in timing) == len(rows)


def test_lagging_agent_hands_over_later_than_reactive(quick_run: Path) -> None:
    """The 0.5 s lag shows up in the paired handover time on the receivers both served."""
    pairs = {
        (p["agent"], p["set"], p["metric"]): p for p in _rows(quick_run / "closed_loop_paired.csv")
    }
    diffs = {
        s: float(pairs[("lagging", s, "handover_time")]["diff"])
        for s in ("walker-id", "walker-ood", "replay-all")
        if int(pairs[("lagging", s, "handover_time")]["n_pairs"])
    }
    # later on straight walks and on the recorded ones; a wanderer (2 quick OOD walkers) loops
    # back to meet a late robot, so there the lag may cost nothing, but it never gains more than
    # one 30 Hz step
    assert diffs["walker-id"] > 0 and diffs["replay-all"] > 0
    assert all(d > -1.0 / 30.0 for d in diffs.values())


def test_results_do_not_depend_on_the_number_of_workers(
    tmp_path: Path, closed_loop_quick: Path
) -> None:
    """The shared run in 2 workers (tests/eval/conftest.py) and the same agents in 1, reusing its
    BC-MLP checkpoint as a rerun does: the same episodes and paired table."""
    shared = json.loads((closed_loop_quick / "DONE").read_text())  # the shared run's argv
    at = shared.index("--workers")
    assert shared[at + 1] == "2"
    shutil.copytree(closed_loop_quick / "checkpoints", tmp_path / "checkpoints")
    argv = shared[:at + 1] + ["1"] + shared[at + 2:] + [
        "--out", str(tmp_path / "1"), "--checkpoints", str(tmp_path / "checkpoints")]
    assert evaluate.main(argv) == 0
    tables = [[{k: v for k, v in r.items() if k != "wall_s"}
               for r in _rows(out / "closed_loop_episodes.csv")]
              for out in (tmp_path / "1", closed_loop_quick / "out")]
    assert len(tables[0]) == 5 * 7 + 3
    assert tables[0] == tables[1]
    assert _rows(tmp_path / "1" / "closed_loop_paired.csv") == _rows(
        closed_loop_quick / "out" / "closed_loop_paired.csv"
    )


def test_replays_of_fold_f_meet_the_fold_f_model() -> None:
    data = generate_synthetic(n=30, ood_fraction=0.2, seed=0)
    folds = fold_of(data, 3, 0)
    splits = data.stratified_kfold(3, 0)
    specs = walkers(2) + replays(data, folds, (1, 2), {}, max_per_fold=2)
    config = ClosedLoopEvalConfig(walkers=2, folds=3, chunk=3)
    jobs = plan_jobs(
        config, specs, splits, MethodOptions(quick=True, workers=1), Path("unused"), "t"
    )
    for job in jobs:
        for spec in job.receivers:
            if job.agent in ("ours", "iaal", "bc-mlp", "act"):
                fold = spec.fold if spec.set == "replay" else 0
                assert job.model_fold == fold
                np.testing.assert_array_equal(job.train_idx, splits[fold][0])
                if spec.set == "replay":  # never trained on the replayed episode
                    assert spec.index not in set(job.train_idx.tolist())
            else:
                assert job.model_fold is None and job.train_idx is None
        assert len({s.set for s in job.receivers}) == 1 and len(job.receivers) <= 3
        if job.agent == "giver-replay":
            assert all(s.set == "replay" for s in job.receivers)
    per_agent = {a: sum(len(j.receivers) for j in jobs if j.agent == a) for a in compared_agents()}
    assert per_agent["giver-replay"] == 4 and per_agent["reactive"] == 8
    assert [s.fold for s in specs if s.set == "replay"] == [1, 1, 2, 2]
    assert [s.seed for s in specs if s.set != "replay"] == [0, 1, 10_000, 10_001]


def test_pick_evenly_spreads_over_the_fold() -> None:
    idx = np.arange(10, 20)
    np.testing.assert_array_equal(pick_evenly(idx, 3), [10, 14, 19])  # round half to even
    np.testing.assert_array_equal(pick_evenly(idx, None), idx)
    np.testing.assert_array_equal(pick_evenly(idx, 50), idx)


def test_episode_row_flattens_info_and_marks_timeouts_and_ghost_releases() -> None:
    spec = ReceiverSpec("replay", "rec_1", 7, fold=5, index=7, recorded_transfer_time=2.0,
                        recorded_pelvis_x=0.4)
    job = EpisodeJob("t", "reactive", (spec,), HandoverParams(), "reach", MethodOptions(workers=1),
                     Path("unused"))
    info = {"outcome": "running", "is_success": False, "handover_time": None, "released": True,
            "release_time": 1.0, "transfer_time": None, "transfer_pelvis_xy": None,
            "transfer_object_pos": None, "penetration": 0.0, "receiver_id": "replay:rec_1"}
    row = episode_row(job, spec, info, 450, 1.5)
    assert row["outcome"] == "timeout" and row["release_before_grasp"]
    assert math.isnan(row["transfer_pelvis_x"]) and math.isnan(row["transfer_object_z"])
    assert (
        math.isnan(row["delta_t"]) and row["steps"] == 450 and row["receiver_id"] == "replay:rec_1"
    )
    info.update(
        outcome="success",
        is_success=True,
        handover_time=2.5,
        release_time=2.5,
        transfer_time=2.2,
        transfer_pelvis_xy=(0.55, -0.9),
        transfer_object_pos=(0.3, -0.5, 1.2),
    )
    row = episode_row(job, spec, info, 80, 0.2)
    assert row["outcome"] == "success" and not row["release_before_grasp"]
    assert row["delta_t"] == pytest.approx(0.2) and row["delta_x"] == pytest.approx(0.15)
    assert (row["transfer_object_x"], row["transfer_object_y"], row["transfer_object_z"]) == (
        0.3,
        -0.5,
        1.2,
    )
    assert (row["fold"], row["model_fold"], row["hand_mode"]) == (5, "", "reach")


def test_quick_theta_sweep_f_r_moves_the_release_force(tmp_path: Path) -> None:
    argv = [
        "theta-sweep",
        "--quick",
        "--no-progress",
        "--agent",
        "reactive",
        "--out",
        str(tmp_path),
        "--checkpoints",
        str(tmp_path / "checkpoints"),
    ]
    assert evaluate.main(argv) == 0
    rows = _rows(tmp_path / "theta_sweep_episodes.csv")
    assert len(rows) == 4 * 3 * 4  # 4 parameters x 3 values x (2 ID + 2 OOD walkers)
    fr = sorted({float(r["f_r"]) for r in rows if r["param"] == "release_force"})
    assert fr == [5.0, 12.5, 20.0]
    assert {float(r["K"]) for r in rows if r["param"] != "stiffness"} == {114.3}
    per_value = _rows(tmp_path / "theta_sweep.csv")
    assert len({(r["param"], r["value"]) for r in per_value}) == 12
    assert {r["set"] for r in per_value} == {"all", "walker-id", "walker-ood"}
    ext = {
        (r["param"], r["set"], r["metric"]): r
        for r in _rows(tmp_path / "theta_sweep_extremes.csv")
    }
    for group in ("all", "walker-id", "walker-ood"):  # the gripper opens at f_r: +15 N
        release = ext[("release_force", group, "release_force")]
        assert 12.0 < float(release["diff"]) < 18.0
    assert ext[("release_force", "all", "release_force")]["ci_excludes_zero"] == "True"
    n_all = {r["param"]: int(r["n_pairs"]) for r in ext.values()
             if r["set"] == "all" and r["metric"] == "success"}
    assert set(n_all.values()) == {4}  # 2 ID + 2 OOD walkers, paired across the extremes
    md = (tmp_path / "theta_sweep.md").read_text()
    assert "f_r (N)" in md and "beyond its noise" in md and "| walker-ood |" in md
    assert (tmp_path / "theta_sweep.png").stat().st_size > 20_000


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["closed-loop", "--agents", "reactive", "robot9000"], "unknown agent"),
        (["closed-loop", "--theta", "-5", "17.1", "0.14", "7.1"], "stiffness"),
        (["closed-loop", "--theta", "114.3", "17.1", "nan", "7.1"], "forecast_time"),
        (["closed-loop", "--data", "/nonexistent/whole_motions"], "no such file"),
        (["closed-loop", "--quick", "--hand-mode", "recorded"], "recorded"),
        (["closed-loop", "--quick", "--replay-folds", "7"], "replay-folds"),
        (["closed-loop", "--sets", "id", "bogus"], "receiver set"),
        (["closed-loop", "--quick", "--agents", "giver-replay", "--sets", "id"], "replays only"),
        (["closed-loop", "--workers", "0"], "workers"),
        (["theta-sweep", "--params", "stiffness", "mass"], "Θ parameter"),
        (["theta-sweep", "--values", "1"], "--values"),
        (["theta-sweep", "--agent", "robot9000"], "unknown agent"),
    ],
)
def test_bad_input_gives_a_clean_error(argv: list[str], message: str, capsys: pytest.CaptureFixture,
                                       tmp_path: Path) -> None:
    assert evaluate.main(argv + ["--no-progress", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.startswith("evaluate.py: error:") and "Traceback" not in err


def test_theta_needs_four_numbers(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit, match="^2$") as exc:
        evaluate.main(["closed-loop", "--theta", "114.3", "17.1"])
    assert exc.value.code == 2 and "--theta" in capsys.readouterr().err


def test_help_explains_every_flag(capsys: pytest.CaptureFixture) -> None:
    for command in ("closed-loop", "theta-sweep"):
        with pytest.raises(SystemExit, match="^0$"):
            evaluate.main([command, "--help"])
        text = capsys.readouterr().out
        for flag in (
            "--data",
            "--replay-folds",
            "--hand-mode",
            "--theta",
            "--checkpoints",
            "--workers",
            "--quick",
            "--bootstrap",
            "--walkers",
        ):
            assert flag in text, (command, flag)


@pytest.mark.skipif(not DATA.is_dir(), reason="development copy of the public dataset not present")
def test_giver_replay_on_recordings_is_compared_with_the_recorded_transfer(tmp_path: Path) -> None:
    argv = [
        "closed-loop",
        "--data",
        str(DATA),
        "--agents",
        "giver-replay",
        "reactive",
        "--sets",
        "replay",
        "--replays-per-fold",
        "2",
        "--replay-folds",
        "5",
        "--hand-mode",
        "recorded",
        "--workers",
        "1",
        "--no-progress",
        "--out",
        str(tmp_path),
    ]
    assert evaluate.main(argv) == 0
    rows = _rows(tmp_path / "closed_loop_episodes.csv")
    assert len(rows) == 4 and {r["hand_mode"] for r in rows} == {"recorded"}
    for r in rows:
        assert r["fold"] == "5" and r["receiver"].startswith("motion_")
        t_rec, t_sim = float(r["recorded_transfer_time"]), float(r["transfer_time"])
        if math.isfinite(t_rec) and math.isfinite(t_sim):
            assert float(r["delta_t"]) == pytest.approx(t_sim - t_rec, abs=1e-4)
    assert any(math.isfinite(float(r["recorded_transfer_time"])) for r in rows)


def test_mujoco_auto_resets_are_counted(monkeypatch, tmp_path: Path) -> None:
    """A NaN velocity makes MuJoCo reset the state mid-step; the row's sim_unstable counts it."""
    import mujoco

    monkeypatch.chdir(tmp_path)  # MuJoCo's warning writes MUJOCO_LOG.TXT into the cwd

    from handover_eval.episodes import instabilities

    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>")
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)
    assert instabilities(data) == 0
    data.qvel[0] = np.nan
    mujoco.mj_step(model, data)
    assert instabilities(data) == 1 and np.all(np.isfinite(data.qvel))


def test_the_paired_reference_is_an_agent_of_the_run(tmp_path: Path) -> None:
    """--reference pairs every agent against another than reactive, on the same receivers; an
    agent not in the run is refused by name."""
    with pytest.raises(ValueError, match="--reference 'cv' is not among --agents"):
        ClosedLoopEvalConfig(agents=("reactive", "null"), reference="cv")
    out = tmp_path / "run"
    assert evaluate.main(["closed-loop", "--quick", "--agents", "cv", "null", "--sets", "id",
                          "--reference", "cv", "--out", str(out), "--no-progress"]) == 0
    pairs = _rows(out / "closed_loop_paired.csv")
    assert pairs and {p["agent"] for p in pairs} == {"null"}
    assert "## Paired against Constant velocity (agent - cv, same receivers)" in (
        out / "closed_loop.md").read_text()
