"""The benchmark: a plug-in agent from a file outside the repo scored on both tracks
with no edit to the project, determinism, the leaderboard and its refusals, rescore byte for byte,
--replay-data fitting on one half and scoring every episode of the other, first-failure
attribution, and the readers' field checks."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from handover_env.data.dataset import HandoverDataset
from handover_env.person.synthetic import generate_synthetic
from handover_eval.benchmark import files, protocol
from handover_eval.benchmark.files import BenchmarkFileError, read_episodes, read_result
from handover_eval.benchmark.leaderboard import LeaderboardError, load_results
from handover_eval.benchmark.outcomes import CHECKS, events, first_failure
from handover_eval.benchmark.output import rescore
from handover_eval.benchmark.plugin import resolve
from handover_eval.cli import evaluate

ROOT = Path(__file__).resolve().parents[2]
TIMING = ("timing",)


def _env() -> dict:
    env = dict(os.environ)
    env.update(PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", HF_HUB_OFFLINE="1")
    return env


def _evaluate(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "evaluate.py"), *args], cwd=cwd,
                          env=_env(), capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def plugin_runs(tmp_path_factory) -> dict[str, Path]:
    """The example agent copied outside the repo, benchmarked twice (--quick), plus the reactive
    reference's closed-loop result, all from a folder outside the repo."""
    tmp = tmp_path_factory.mktemp("bench")
    elsewhere = tmp / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(ROOT / "examples" / "my_agent.py", elsewhere / "my_agent.py")
    runs = {}
    for name, args in (
        ("a", ["--agent", "elsewhere/my_agent.py:make_agent", "--name", "ridge"]),
        ("b", ["--agent", "elsewhere/my_agent.py:make_agent", "--name", "ridge"]),
        ("reactive", ["--agent", "reactive", "--tracks", "closedloop"]),
    ):
        proc = _evaluate(["benchmark", *args, "--quick", "--no-progress", "--workers", "1",
                          "--checkpoints", str(tmp / "ckpt"), "--out", str(tmp / name)], tmp)
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs[name] = tmp / name
    runs["tmp"] = tmp
    return runs


def test_plugin_outside_the_repo_is_scored_on_both_tracks(plugin_runs) -> None:
    result = read_result(plugin_runs["a"] / "result.json")
    assert result["protocol_version"] == protocol.PROTOCOL_VERSION and result["quick"] is True
    assert result["agent"]["name"] == "ridge" and result["agent"]["kind"] == "plugin"
    assert result["agent"]["config"]["config"] == {"horizon": 30, "ridge": 0.001, "window": 8}
    assert result["tracks"] == ["openloop", "closedloop"]
    ol = result["metrics"]["openloop"]
    for s in ("id", "ood", "all"):
        m = ol[s]["rms_now_axis_mm"]
        assert 0 < m["low"] <= m["value"] <= m["high"] and m["n"] > 0
    assert ol["all"]["rms_now_axis_mm"]["n"] == 30  # every quick episode tested once
    cl = result["metrics"]["closedloop"]
    assert set(cl) == {*protocol.CLOSEDLOOP_SETS, "all"}
    assert cl["all"]["n"] == 3 * protocol.QUICK_WALKERS + protocol.QUICK_REPLAYS
    for s in protocol.CLOSEDLOOP_SETS:
        assert cl[s]["paired"] is not None  # paired against the reactive reference
        k, n = cl[s]["success"]["k"], cl[s]["n"]
        assert cl[s]["success"]["value"] == pytest.approx(k / n)
        assert sum(cl[s]["first_failure"].values()) == n - k
    _, rows = read_episodes(plugin_runs["a"] / "closedloop_episodes.csv")
    assert {r["agent"] for r in rows} == {"ridge", "reactive"}
    far = [r for r in rows if r["set"] == "far-pass"]
    assert far and all(protocol.FAR_PASS_Y[0] <= r["pass_y"] <= protocol.FAR_PASS_Y[1]
                       for r in far)
    assert all(r["seed"] >= protocol.TRAIN_SEED_LIMIT for r in rows if r["set"].startswith(
        ("walker", "far")))
    assert result["episodes"]["closedloop"]["sha256"] == files.sha256_file(
        plugin_runs["a"] / "closedloop_episodes.csv")


def test_the_same_command_gives_the_same_result(plugin_runs) -> None:
    a, b = (json.loads((plugin_runs[k] / "result.json").read_text()) for k in ("a", "b"))
    for k in TIMING:
        a.pop(k), b.pop(k)
    assert a == b
    for name in ("openloop_episodes.csv", "closedloop_episodes.csv", "benchmark.md"):
        assert (plugin_runs["a"] / name).read_bytes() == (plugin_runs["b"] / name).read_bytes()


def test_leaderboard_ranks_result_files(plugin_runs) -> None:
    tmp = plugin_runs["tmp"]
    proc = _evaluate(["leaderboard", str(plugin_runs["a"] / "result.json"),
                      str(plugin_runs["reactive"] / "result.json"), "--out", str(tmp / "lb")], tmp)
    assert proc.returncode == 0, proc.stderr
    md = (tmp / "lb" / "leaderboard.md").read_text()
    assert "| ridge (quick) |" in md and "| reactive (quick) |" in md
    assert f"protocol v{protocol.PROTOCOL_VERSION}" in md
    assert (tmp / "lb" / "leaderboard.png").stat().st_size > 10_000
    # the same agent twice is refused
    proc = _evaluate(["leaderboard", str(plugin_runs["a"] / "result.json"),
                      str(plugin_runs["b"] / "result.json"), "--out", str(tmp / "lb2")], tmp)
    assert proc.returncode == 2 and "two results are for agent 'ridge'" in proc.stderr


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("evaluate.py: error:") and "\n" not in err, err
    return err


def test_leaderboard_refuses_mixed_versions_and_fingerprints(plugin_runs, tmp_path, capsys,
                                                             monkeypatch) -> None:
    data = json.loads((plugin_runs["a"] / "result.json").read_text())
    old = json.loads(json.dumps(data))  # a v1 result (the first person)
    old["protocol_version"], old["agent"]["name"] = 1, "other"
    for fp in old["fingerprints"].values():
        fp["protocol_version"] = 1
    (tmp_path / "v1.json").write_text(json.dumps(old))
    ref = str(plugin_runs["reactive"] / "result.json")
    out = ["--out", str(tmp_path / "lb")]
    assert evaluate.main(["leaderboard", ref, str(tmp_path / "v1.json"), *out]) == 2
    err = _one_line_error(capsys)
    assert "protocol version 1" in err and "not comparable" in err
    # a file of a version this code does not know is refused on its own too
    unknown = max(protocol.KNOWN_VERSIONS) + 1
    future = dict(data, protocol_version=unknown, agent=dict(data["agent"], name="other"))
    (tmp_path / "future.json").write_text(json.dumps(future))
    assert evaluate.main(["leaderboard", str(tmp_path / "future.json"), *out]) == 2
    assert "field protocol_version must be a known protocol version" in _one_line_error(capsys)
    # the same version but another fingerprint (other receivers or data)
    other = json.loads(json.dumps(data))
    other["agent"]["name"] = "other"
    other["fingerprints"]["closedloop"]["fingerprint"] = "0" * 32
    other["fingerprints"]["closedloop"]["receivers"] = "1" * 32
    (tmp_path / "fp.json").write_text(json.dumps(other))
    assert evaluate.main(["leaderboard", ref, str(tmp_path / "fp.json"), *out]) == 2
    err = _one_line_error(capsys)
    assert "closedloop fingerprint" in err and "receivers" in err


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d["metrics"]["closedloop"]["all"]["success"].update(value="0.9"),
         "metrics.closedloop.all.success.value must be a finite number or null"),
        (lambda d: d["agent"].update(name="a|b\nc"), "field agent.name must be an agent name"),
        (lambda d: d.update(extra=1), "has unknown field(s) ['extra']"),
        (lambda d: d["metrics"]["openloop"].update(train={}), "metrics.openloop.train is not one"),
        (lambda d: d["fingerprints"]["openloop"].update(data="../x"),
         "fingerprints.openloop.data must be 32 hex digits"),
        (lambda d: d["metrics"]["closedloop"]["all"].pop("n"),
         "field metrics.closedloop.all lacks"),
    ],
)
def test_result_fields_are_checked(plugin_runs, tmp_path, edit, message) -> None:
    data = json.loads((plugin_runs["a"] / "result.json").read_text())
    edit(data)
    path = tmp_path / "r.json"
    path.write_text(json.dumps(data))
    with pytest.raises(BenchmarkFileError, match=re.escape(message)) as exc:
        read_result(path)
    assert message in str(exc.value) and str(path) in str(exc.value)


def test_result_json_is_parsed_safely(tmp_path) -> None:
    for text, message in (('{"a": 1, "a": 2}', "duplicate key"), ('{"a": NaN}', "NaN"),
                          ("[" * 100_000, "not a result file"), ("{}", "protocol_version")):
        path = tmp_path / "r.json"
        path.write_text(text)
        with pytest.raises(BenchmarkFileError, match=message):
            load_results([path])
    path.write_text(" " * (files.MAX_JSON_BYTES + 1))
    with pytest.raises(BenchmarkFileError, match="allowed"):
        read_result(path)
    with pytest.raises(LeaderboardError, match="no result file"):
        load_results([])


def test_rescore_rebuilds_the_tables_byte_for_byte(plugin_runs, tmp_path, capsys) -> None:
    run = plugin_runs["a"]
    eps = [str(run / "closedloop_episodes.csv"), str(run / "openloop_episodes.csv")]
    assert evaluate.main(["rescore", *eps, "--out", str(tmp_path / "r")]) == 0
    for name in ("benchmark.md", "closedloop_table.csv", "openloop_table.csv"):
        assert (tmp_path / "r" / name).read_bytes() == (run / name).read_bytes(), name
    # ... from the episodes alone: one changed outcome changes the table
    rows = list(csv.DictReader((run / "closedloop_episodes.csv").open()))
    first = next(r for r in rows if r["agent"] == "ridge")
    first.update(success="False", outcome="missed", first_failure="no_grasp")
    changed = tmp_path / "changed.csv"
    with changed.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    _, written = rescore([changed], tmp_path / "c")
    md = (tmp_path / "c" / "benchmark.md").read_text()
    assert "no_grasp 1" in md and md != (run / "benchmark.md").read_text()
    assert written[-1].name == "benchmark.md"


def test_rescore_joins_runs_and_pairs_against_another_reference(plugin_runs, tmp_path,
                                                                 capsys) -> None:
    a, ref = (plugin_runs[k] / "closedloop_episodes.csv" for k in ("a", "reactive"))
    out = tmp_path / "j"
    assert evaluate.main(["rescore", str(a), str(ref), "--reference", "ridge", "--out",
                          str(out)]) == 0
    assert "success − ridge" in (out / "benchmark.md").read_text()
    joined = {(r["agent"], r["set"]): r for r in csv.DictReader((out / "closedloop_table.csv"
                                                                  ).open())}
    usual = {(r["agent"], r["set"]): r for r in csv.DictReader(
        (plugin_runs["a"] / "closedloop_table.csv").open())}
    assert joined.keys() == usual.keys()  # reactive's rows of both files were the same
    for (agent, rset), row in joined.items():
        if agent == "ridge":
            assert row["paired_success_diff"] in ("", "nan")
        else:  # a mean paired difference changes sign with the reference
            assert float(row["paired_success_diff"]) == -float(
                usual[("ridge", rset)]["paired_success_diff"])
    rows = list(csv.DictReader(ref.open()))
    rows[0]["handover_time"] = "9.5" if rows[0]["success"] == "True" else rows[0]["handover_time"]
    rows[0]["seed"] = str(int(rows[0]["seed"]) + 1)
    other = tmp_path / "other.csv"
    with other.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    capsys.readouterr()
    assert evaluate.main(["rescore", str(a), str(other), "--out", str(tmp_path / "k")]) == 2
    assert "reactive's closedloop episodes differ" in capsys.readouterr().err
    assert evaluate.main(["rescore", str(ref), "--reference", "cv", "--out",
                          str(tmp_path / "m")]) == 2
    assert "no closed-loop episodes of the reference agent 'cv'" in capsys.readouterr().err


@pytest.mark.parametrize(
    "column, value, message",
    [
        ("success", "yes", "success: 'yes' is not True or False"),
        ("set", "train", "set: 'train' is not one of"),
        ("handover_time", "1e999", "handover_time: '1e999' is not a finite number"),
        ("handover_time", "__import__('os')", "is not a finite number"),
        ("first_failure", "no_grasp", "contradicts success"),
        ("seed", "1.5", "seed: '1.5' is not an integer"),
    ],
)
def test_episode_files_are_checked(plugin_runs, tmp_path, column, value, message, capsys) -> None:
    rows = list(csv.DictReader((plugin_runs["a"] / "closedloop_episodes.csv").open()))
    i = next(k for k, r in enumerate(rows) if r["success"] == "True")  # a success to contradict
    rows[i][column] = value
    path = tmp_path / "bad.csv"
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    assert evaluate.main(["rescore", str(path), "--out", str(tmp_path / "r")]) == 2
    err = _one_line_error(capsys)
    assert message in err and str(path) in err and f"line {i + 2}, " in err
    assert not (tmp_path / "r" / "benchmark.md").exists()


def test_replay_data_fits_on_dev_only_and_scores_every_other_episode(tmp_path, capsys) -> None:
    data = generate_synthetic(n=30, ood_fraction=0.2, seed=0)
    dev_idx = [i for i in range(30) if i % 5 != 2]  # 24 episodes (ID and OOD)
    other_idx = [i for i in range(30) if i % 5 == 2]  # 6 others
    dev, other = data.subset(dev_idx), data.subset(other_idx)
    assert other.ood_mask.any() and not set(e.source_id for e in dev) & {
        e.source_id for e in other}
    dev_path, other_path = dev.save(tmp_path / "dev.npz"), other.save(tmp_path / "other.npz")
    dev_print, other_print = (HandoverDataset.load(p).fingerprint() for p in (dev_path,
                                                                              other_path))
    common = ["--quick", "--no-progress", "--workers", "1", "--data", str(dev_path),
              "--replay-data", str(other_path)]
    # Table I: one fit on all of DEV, every episode of OTHER scored.
    out = tmp_path / "t1"
    assert evaluate.main(["table1", *common, "--methods", "ours", "cv", "--out", str(out)]) == 0
    eps = list(csv.DictReader((out / "table1_episodes.csv").open()))
    assert sorted(r["source_id"] for r in eps if r["method"] == "ours") == sorted(
        e.source_id for e in other)
    folds = list(csv.DictReader((out / "table1_folds.csv").open()))
    assert {(r["n_train"], r["train_fingerprint"]) for r in folds} == {("24", dev_print)}
    assert "every episode of --replay-data" in (out / "table1.md").read_text()
    # closed loop: the learning agent fit on DEV meets every recording of OTHER.
    out = tmp_path / "cl"
    argv = ["closed-loop", *common, "--agents", "ours", "--sets", "replay", "--checkpoints",
            str(tmp_path / "ck"), "--out", str(out)]
    assert evaluate.main(argv) == 0
    rows = list(csv.DictReader((out / "closed_loop_episodes.csv").open()))
    assert sorted(r["receiver"] for r in rows) == sorted(e.source_id for e in other)
    assert {r["model_fold"] for r in rows} == {"-1"} and {r["fold"] for r in rows} == {""}
    models = list(csv.DictReader((out / "closed_loop_models.csv").open()))
    assert [m["n_train"] for m in models] == ["24"]
    # the benchmark records both fingerprints
    out = tmp_path / "bm"
    assert evaluate.main(["benchmark", "--agent", "cv", "--tracks", "openloop", *common,
                          "--out", str(out)]) == 0
    fp = read_result(out / "result.json")["fingerprints"]["openloop"]
    assert (fp["data"], fp["replay_data"]) == (dev_print, other_print)
    assert read_result(out / "result.json")["metrics"]["openloop"]["all"]["ade_10_mm"]["n"] == 6
    capsys.readouterr()
    # recordings that are also in --data are refused
    assert evaluate.main(["table1", "--quick", "--no-progress", "--data", str(dev_path),
                          "--replay-data", str(dev_path), "--methods", "cv", "--out",
                          str(tmp_path / "x")]) == 2
    assert "shares 24 episode(s) with --data" in _one_line_error(capsys)


def _row(**kw) -> dict:
    base = {"outcome": "missed", "sim_unstable": 0, "release_before_grasp": False,
            "reach_onset_time": 1.0, "transfer_time": 1.5, "released": True,
            "body_contact_force": 0.0, "penetration": 0.0}
    return {**base, **kw}


@pytest.mark.parametrize(
    "row, cause",
    [
        (_row(outcome="success"), ""),
        (_row(outcome="success", sim_unstable=2), "unstable"),  # a void success is a failure
        (_row(outcome="unsafe_force", release_before_grasp=True), "unsafe_force"),
        (_row(outcome="premature_release", transfer_time=math.nan), "premature_release"),
        (_row(reach_onset_time=math.nan, transfer_time=math.nan, released=False), "no_reach"),
        (_row(transfer_time=math.nan, released=False), "no_grasp"),
        (_row(outcome="timeout", released=False), "no_release"),
        (_row(outcome="dropped"), "dropped"),
        (_row(outcome="timeout"), "not_cleared"),
    ],
)
def test_first_failure_is_the_first_failed_check(row, cause) -> None:
    ev = events(row)
    assert first_failure(row["outcome"], ev) == cause
    assert cause == "" or cause in CHECKS


def test_events_flag_everything_that_happened() -> None:
    ev = events(_row(outcome="unsafe_force", release_before_grasp=True, body_contact_force=40.0,
                     penetration=0.02))
    assert ev["unsafe_force"] and ev["premature_release"] and ev["body_contact"]
    assert ev["penetration_over_1cm"] and ev["reached"] and ev["grasped"] and not ev["timeout"]


def test_agent_specs(tmp_path) -> None:
    assert resolve("bc-mlp").target == "bc_mlp" and resolve("reactive").tracks == ("closedloop",)
    for spec, message in (("gpt", "not a built-in"), ("x.py:make", "no such file"),
                          ("os.path:1x", "not a Python name"), ("nonexistent_pkg.m:f",
                                                                "no module named")):
        with pytest.raises(ValueError, match=message):
            resolve(spec)
    (tmp_path / "a.py").write_text("def make():\n    return object()\n")
    src = resolve(f"{tmp_path / 'a.py'}:make", config='{"k": 1}')
    assert src.kind == "plugin" and src.kwargs() == {"k": 1} and len(src.source_sha256) == 64
    for config, message in (("[1]", "JSON object"), ('{"1x": 2}', "identifiers"),
                            ('{"a": NaN}', "NaN")):
        with pytest.raises(ValueError, match=message):
            resolve(f"{tmp_path / 'a.py'}:make", config=config)
    from handover_eval.benchmark.plugin import build_plugin

    with pytest.raises(ValueError, match="not an agents.base.Agent"):
        build_plugin(resolve(f"{tmp_path / 'a.py'}:make"))


def test_help_says_a_plugin_runs_its_code(capsys) -> None:
    with pytest.raises(SystemExit, match="^0$"):
        evaluate.main(["benchmark", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Loading a plug-in agent runs its code" in text
    for flag in ("--agent", "--agent-config", "--tracks", "--data", "--replay-data", "--quick",
                 "--name", "--out", "--workers"):
        assert flag in text


def test_the_closed_loop_track_runs_the_protocols_sensing_profile() -> None:
    """v1 is scored on the paper profile, passed to the env explicitly (a later change of the
    env's default cannot move v1's numbers), and that profile is the env's default today."""
    import gymnasium as gym

    from handover_eval.benchmark.closed_loop import clear_state, track_env

    assert protocol.SENSING == "paper"
    try:
        env = track_env(protocol.THETA).unwrapped
        assert env.sensing == protocol.SENSING
        assert env.params == protocol.THETA
    finally:
        clear_state()
    default = gym.make(protocol.ENV_ID).unwrapped
    try:
        assert default.sensing == protocol.SENSING
    finally:
        default.close()


def test_a_missing_replay_data_path_is_refused_before_any_run(tmp_path, capsys) -> None:
    missing = tmp_path / "nowhere"
    assert evaluate.main(["benchmark", "--agent", "cv", "--quick", "--no-progress",
                          "--replay-data", str(missing), "--out", str(tmp_path / "b")]) == 2
    assert f"--replay-data {missing}: no such file or folder" in capsys.readouterr().err
    assert not (tmp_path / "b" / "result.json").exists()
