"""The benchmark's result files under attack (issue 32, R3-R4 and R6-R11): every crafted input is
built here and ends in one error naming the file, the field (and line) or the agent, or, for R6,
in a correct figure; nothing is written outside ``--out``.

R3: a blocked bootstrap, the same CI bit for bit, in bounded memory; R4: agents and rows a file
may hold; R6: a 25/25 set in the leaderboard figure; R7: result.json values against each other;
R8: full matches; R9: value ranges; R11: huge predictions stop the run naming the agent and the
episode, and a result is ranked only beside its own episode files.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from handover_env.person.synthetic import generate_synthetic
from handover_eval.benchmark import files, leaderboard, output, protocol, result_values
from handover_eval.benchmark.files import (
    CLOSEDLOOP_COLUMNS,
    OPENLOOP_COLUMNS,
    BenchmarkFileError,
    read_episodes,
    read_result,
)
from handover_eval.benchmark.leaderboard import (
    LeaderboardError,
    leaderboard_figure,
    load_results,
)
from handover_eval.benchmark.outcomes import EVENTS
from handover_eval.benchmark.plugin import AgentSource
from handover_eval.benchmark.run import BenchmarkRun
from handover_eval.cli import evaluate
from handover_eval.closedloop import stats
from handover_eval.reporting import write_csv

ROOT = Path(__file__).resolve().parents[2]
FLOATS = [c for c, p in CLOSEDLOOP_COLUMNS.items() if c in (
    "handover_time", "transfer_time", "reach_onset_time", "release_time", "release_force",
    "peak_contact_force", "body_contact_force", "penetration", "time_lost", "reach_distance",
    "arm_extended_time", "pull_force", "robot_jerk_rms", "delta_t", "delta_x")]


# ------------------------------------------------------------------------------- crafted files
def closed_row(agent: str, bench_set: str, i: int, success: bool = True, **kw) -> dict:
    """One closed-loop episode row as a run produces it (a success or a missed handover)."""
    row = {"agent": agent, "set": bench_set, "receiver": f"{bench_set}-{i:04d}",
           "seed": protocol.TEST_SEEDS.get(bench_set, 0) + i, "fold": "", "model_fold": "",
           "is_ood": bench_set.endswith("ood"), "pass_y": math.nan,
           "outcome": "success" if success else "missed", "success": success,
           "first_failure": "" if success else "no_grasp",
           **{f"ev_{e}": e in ("reached", "grasped", "released") and success for e in EVENTS}}
    row.update({c: 1.0 + 0.01 * ((7 * i + 3 * k) % 50) for k, c in enumerate(FLOATS)})
    row.update(delta_t=math.nan, delta_x=math.nan, sim_unstable=0, steps=60 + i)
    if not success:
        row.update(handover_time=math.nan, transfer_time=math.nan, release_time=math.nan)
    row.update(kw)
    return row


def open_row(agent: str, i: int, **kw) -> dict:
    row = {"agent": agent, "fold": i % 3, "source_id": f"ep{i:04d}", "is_ood": i % 4 == 0,
           "n_queries": 40, **{m: 50.0 + (13 * i + 7 * k) % 40
                               for k, m in enumerate(protocol.OPENLOOP_METRICS)}}
    row.update(kw)
    return row


def closed_rows(agent: str, per_set: int = 4, fail_every: int = 3) -> list[dict]:
    """``agent``'s rows and the reference's, ``per_set`` receivers of every set."""
    rows = []
    for name in (agent, protocol.REFERENCE_AGENT):
        for s in protocol.CLOSEDLOOP_SETS:
            rows += [closed_row(name, s, i, success=(i + len(name)) % fail_every != 0)
                     for i in range(per_set)]
    return rows


def fingerprints(tracks: tuple[str, ...]) -> dict:
    base = {"protocol_version": protocol.PROTOCOL_VERSION, "data": "d" * 32, "replay_data": None,
            "protocol": {}}
    out = {"openloop": {"fingerprint": "a" * 32, **base},
           "closedloop": {"fingerprint": "b" * 32, **base, "receivers": "c" * 32,
                          "n_receivers": 25}}
    return {t: out[t] for t in tracks}


def write_run(out: Path, agent: str = "mine", rows: dict | None = None) -> Path:
    """A benchmark folder as a run writes it (:func:`.output.write_benchmark`), from crafted
    rows; returns its result.json."""
    rows = rows or {"openloop": [open_row(agent, i) for i in range(12)],
                    "closedloop": closed_rows(agent)}
    tracks = tuple(t for t in protocol.TRACKS if t in rows)
    source = AgentSource(agent, "plugin", "/x/mine.py", "make", spec="mine.py:make")
    run = BenchmarkRun(source, tracks, protocol.BenchmarkSettings(quick=True), rows,
                       fingerprints(tracks), {"kwargs": {}})
    output.write_benchmark(run, out)
    return out / files.RESULT_NAME


def edited(path: Path, edit, name: str = "edited") -> Path:
    """A copy of ``path`` (a result.json) with ``edit`` applied, beside the same episode files."""
    data = json.loads(path.read_text())
    edit(data)
    new = path.parent / f"{name}.json"
    new.write_text(json.dumps(data))
    return new


def write_episode_csv(path: Path, rows: list[dict], columns) -> Path:
    return write_csv([{c: r[c] for c in columns} for r in rows], path)


def listing(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` and its bytes (a before/after snapshot)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


@pytest.fixture()
def run_dir(tmp_path) -> Path:
    return write_run(tmp_path / "run")


# ----------------------------------------------------------------------------------------- R3
@pytest.mark.parametrize("stat", ["median", "mean"])
def test_bootstrap_blocks_draw_the_same_resamples(stat, monkeypatch) -> None:
    """Blocks of any size give the CI of one (B, n) draw, bit for bit."""
    rng = np.random.default_rng(5)
    for n in (2, 3, 17, 250, 1001):
        v = rng.normal(size=n) * 10.0 ** rng.uniform(-3, 3, size=n)
        whole = stats.bootstrap_ci(v, stat, 2000, n)
        for block in (1, 7 * n + 3, 333 * n):
            monkeypatch.setattr(stats, "BOOTSTRAP_BLOCK", block)
            assert stats.bootstrap_ci(v, stat, 2000, n) == whole, (n, block)
        monkeypatch.undo()
    # the one-shot draw it replaces, written out
    v = rng.normal(size=40)
    idx = np.random.default_rng(3).integers(0, 40, size=(2000, 40))
    boot = np.median(v[idx], axis=1) if stat == "median" else np.mean(v[idx], axis=1)
    alpha = (1.0 - 0.95) / 2.0  # 0.025000000000000022, as bootstrap_ci computes it
    lo, hi = np.quantile(boot, [alpha, 1.0 - alpha])
    assert stats.bootstrap_ci(v, stat, 2000, 3)[1:] == (float(lo), float(hi))


def test_bootstrap_memory_is_one_block(monkeypatch) -> None:
    """tracemalloc's peak over a bootstrap of 20,000 values: about one block of resamples, not
    the 2 x 2000 x 20,000 x 8 bytes (640 MB) of a one-shot draw."""
    import tracemalloc

    monkeypatch.setattr(stats, "BOOTSTRAP_BLOCK", 1 << 18)  # 2 MiB of indices
    v = np.random.default_rng(0).normal(size=20_000)
    tracemalloc.start()
    try:
        stats.bootstrap_ci(v, "median", 2000, 0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 12 * (1 << 20), peak


RSS_SCRIPT = textwrap.dedent("""
    import resource, sys
    from pathlib import Path
    from handover_eval.benchmark.output import rescore
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rescore([Path(sys.argv[1])], Path(sys.argv[2]))
    print(before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
""")


def test_rescore_peak_memory_is_bounded(tmp_path) -> None:
    """rescore of 12,000 successes of one agent: peak RSS grows by far less than the 2000 x 12,000
    x 8 bytes x 3 (576 MB) that one-shot resamples (indices, values, the median's copy) held."""
    rows = [closed_row(protocol.REFERENCE_AGENT, "walker-id", i) for i in range(12_000)]
    path = write_episode_csv(tmp_path / "big.csv", rows, CLOSEDLOOP_COLUMNS)
    proc = subprocess.run([sys.executable, "-c", RSS_SCRIPT, str(path), str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path,
                          env=dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    before, after = (int(x) for x in proc.stdout.split())
    grew_mb = (after - before) / 1024
    assert grew_mb < 250, f"peak RSS grew by {grew_mb:.0f} MB"
    assert (tmp_path / "out" / "closedloop_table.csv").exists()


# ----------------------------------------------------------------------------------------- R4
def test_an_episode_file_holds_a_bounded_number_of_agents_and_rows(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(files, "MAX_AGENTS", 3)
    rows = [closed_row(f"agent{i}", "walker-id", 0) for i in range(4)]
    path = write_episode_csv(tmp_path / "agents.csv", rows, CLOSEDLOOP_COLUMNS)
    with pytest.raises(BenchmarkFileError, match=r"agents\.csv: line 5, agent: more than 3 "
                                                 "agents in one file"):
        read_episodes(path)
    monkeypatch.setattr(files, "MAX_ROWS", 5)
    path = write_episode_csv(tmp_path / "rows.csv", [open_row("a", i) for i in range(6)],
                             OPENLOOP_COLUMNS)
    with pytest.raises(BenchmarkFileError, match=r"rows\.csv: more than 5 rows"):
        read_episodes(path)


def test_the_stated_limits_are_the_measured_ones() -> None:
    """The limits the docs state (docs/security.md, 'Result files') are the code's."""
    text = (ROOT / "docs" / "security.md").read_text()
    assert f"{files.MAX_ROWS:,} rows" in text and f"{files.MAX_AGENTS:,} agents" in text
    assert f"{files.MAX_CSV_BYTES // 1_000_000} MB" in text
    assert f"{files.MAX_JSON_BYTES // 1000} kB" in text
    assert f"{leaderboard.MAX_RESULTS} result files" in text


# ----------------------------------------------------------------------------------------- R6
def test_leaderboard_figure_of_a_perfect_set(tmp_path) -> None:
    """25/25 in one set: its Wilson high is 0.9999999999999999, the bar's upper error 0, not a
    negative yerr; the figure shows the bar at 100 % with its interval below."""
    rows = [closed_row("perfect", "walker-id", i) for i in range(25)]
    rows += [closed_row(protocol.REFERENCE_AGENT, "walker-id", i, success=i % 2 == 0)
             for i in range(25)]
    result = write_run(tmp_path / "run", "perfect", {"closedloop": rows})
    s = read_result(result)["metrics"]["closedloop"]["walker-id"]["success"]
    assert (s["k"], s["value"]) == (25, 1.0) and s["high"] < 1.0
    fig = leaderboard_figure(load_results([result]))
    bars = fig.axes[0].containers  # per set: the bars, then the error bars
    walker_bars = [c for c in bars if hasattr(c, "patches")][0]
    assert walker_bars.patches[0].get_height() == pytest.approx(100.0)
    segments = [seg for coll in fig.axes[0].collections for seg in coll.get_segments()
                if len(seg) == 2 and np.isfinite(seg).all()]  # sets without episodes: no bar
    assert segments and all(seg[0][1] <= seg[1][1] for seg in segments)
    top = max(seg[1][1] for seg in segments)
    assert top == pytest.approx(100.0) and min(seg[0][1] for seg in segments) == pytest.approx(
        100 * s["low"])
    out = tmp_path / "lb"
    assert evaluate.main(["leaderboard", str(result), "--out", str(out)]) == 0
    assert (out / "leaderboard.png").stat().st_size > 10_000
    assert "| perfect (quick) | 100 % [87, 100]" in (out / "leaderboard.md").read_text()


# ----------------------------------------------------------------------------------------- R7
CL = ("metrics", "closedloop")


def _set(path: tuple, value) -> callable:
    def edit(d: dict) -> None:
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value

    return edit


@pytest.mark.parametrize(
    "edit, field, what",
    [
        (_set((*CL, "all", "success", "low"), None), "metrics.closedloop.all.success.low",
         "null although n >= 1"),
        (_set((*CL, "all", "handover_time", "high"), None),
         "metrics.closedloop.all.handover_time.high", "null although n is"),
        (_set((*CL, "walker-id", "success", "value"), 7.0),
         "metrics.closedloop.walker-id.success.value", "is not k / n"),
        (_set((*CL, "walker-id", "success", "value"), -0.5),
         "metrics.closedloop.walker-id.success.value", "is not k / n"),
        (_set((*CL, "all", "n"), 10**400), "metrics.closedloop.all.n",
         "must be a finite number of magnitude at most 2**53, got 1000000"),
        (_set((*CL, "all", "handover_time", "value"), 2**53 + 1),
         "metrics.closedloop.all.handover_time.value", "a finite number of magnitude at most"),
        (_set(("agent", "config", "big"), -(10**400)), "agent.config.big",
         "a finite number of magnitude at most 2**53, got -1000000"),
        (_set((*CL, "walker-id", "n"), 10**10), "metrics.closedloop.walker-id.n",
         "must be an integer in [0, 1e9]"),
        (_set((*CL, "walker-id", "success", "k"), 5), "metrics.closedloop.walker-id.success.k",
         "5 successes out of n = 4"),
        (_set((*CL, "walker-id", "success", "high"), 0.999),
         "metrics.closedloop.walker-id.success", "is not the Wilson interval"),
        (_set((*CL, "all", "handover_time", "low"), 99.0),
         "metrics.closedloop.all.handover_time", "not low <= value <= high"),
        (_set((*CL, "all", "handover_time", "n"), 20),
         "metrics.closedloop.all.handover_time.n", "more than the"),
        (_set((*CL, "far-pass", "first_failure", "dropped"), 3),
         "metrics.closedloop.far-pass.first_failure", "failures, n - k ="),
        (_set((*CL, "far-pass", "paired", "success", "diff"), 1.5),
         "metrics.closedloop.far-pass.paired.success.diff", "outside [-1.0, 1.0]"),
        (_set((*CL, "all", "handover_time", "value"), -1.0),
         "metrics.closedloop.all.handover_time.value", "outside [0.0, None]"),
        (_set(("metrics", "openloop", "all", "rms_3d_mm", "low"), -3.0),
         "metrics.openloop.all.rms_3d_mm.low", "outside [0.0, None]"),
        (_set(("metrics", "openloop", "id", "ade_10_mm", "n"), 4),
         "metrics.openloop.all.ade_10_mm.n", "is not the episodes of id and ood"),
        (lambda d: d["metrics"]["closedloop"].pop("all"), "metrics.closedloop",
         "lacks the set 'all'"),
        (_set(("episodes", "closedloop", "rows"), 0), "episodes.closedloop.rows",
         "at least one row"),
    ],
)
def test_result_values_are_checked_against_each_other(run_dir, tmp_path, capsys, edit, field,
                                                       what) -> None:
    bad = edited(run_dir, edit)
    with pytest.raises(BenchmarkFileError) as exc:
        load_results([bad])
    message = str(exc.value)
    assert message.startswith(f"{bad}: field {field}") and what in message, message
    assert "\n" not in message
    out = tmp_path / "lb"
    assert evaluate.main(["leaderboard", str(bad), "--out", str(out)]) == 2
    assert f"field {field}" in capsys.readouterr().err
    assert not (out / "leaderboard.md").exists()


def test_the_crafted_run_is_a_valid_result(run_dir) -> None:
    result = read_result(run_dir)
    assert load_results([run_dir])[0][1] == result
    assert result_values.value_problem(result) is None
    assert result["metrics"]["closedloop"]["all"]["paired"] is not None


# ----------------------------------------------------------------------------------------- R8
@pytest.mark.parametrize(
    "column, value, message",
    [
        ("receiver", "walker-id-0001\n", "receiver: 'walker-id-0001\\\\n' is not allowed here"),
        ("agent", "evil\n", "agent: 'evil\\\\n' is not allowed here"),
        ("seed", "200000001\n", "seed: '200000001\\\\n' is not an integer"),
        ("handover_time", "1.5\n", "handover_time: '1.5\\\\n' is not a finite number"),
    ],
)
def test_a_trailing_newline_is_not_a_match(tmp_path, column, value, message) -> None:
    """A receiver 'x\\n' would be a second copy of receiver 'x' (the 'appears twice' check
    passed and the success rate moved); an agent 'evil\\n' a new agent that breaks the tables."""
    rows = closed_rows("mine")
    target = next(i for i, r in enumerate(rows) if r["agent"] == "mine" and r["success"]
                  and r["receiver"] != "walker-id-0001")
    rows[target][column] = value
    if column == "receiver":
        rows[target]["set"] = "walker-id"
    path = write_episode_csv(tmp_path / "nl.csv", rows, CLOSEDLOOP_COLUMNS)
    with pytest.raises(BenchmarkFileError, match=rf"nl\.csv: line {target + 2}, {message}"):
        read_episodes(path)


@pytest.mark.parametrize(
    "edit, field",
    [
        (_set(("agent", "name"), "evil\n"), "agent.name must be an agent name"),
        (_set(("fingerprints", "closedloop", "data"), "d" * 32 + "\n"),
         "fingerprints.closedloop.data must be 32 hex digits"),
        (_set(("episodes", "openloop", "sha256"), "0" * 64 + "\n"),
         "episodes.openloop.sha256 must be 64 hex digits"),
    ],
)
def test_a_trailing_newline_in_result_json_is_refused(run_dir, edit, field) -> None:
    bad = edited(run_dir, edit)
    with pytest.raises(BenchmarkFileError, match=rf"edited\.json: field {field}"):
        read_result(bad)


# ----------------------------------------------------------------------------------------- R9
@pytest.mark.parametrize(
    "column, value, message",
    [
        ("handover_time", -1.5, "handover_time: '-1.5' is negative"),
        ("peak_contact_force", -3.0, "peak_contact_force: '-3' is negative"),
        ("steps", -5, "steps: -5 is below 0"),
        ("seed", -1, "seed: -1 is below 0"),
        ("model_fold", -2, "model_fold: -2 is below -1"),
        ("fold", 10, "fold: 10 is not below 10"),
        ("handover_time", math.nan, r"handover_time: nan on a success"),
    ],
)
def test_episode_values_are_in_range(tmp_path, capsys, column, value, message) -> None:
    rows = closed_rows("mine")
    target = next(i for i, r in enumerate(rows) if r["success"])
    rows[target][column] = value
    path = write_episode_csv(tmp_path / "bad.csv", rows, CLOSEDLOOP_COLUMNS)
    with pytest.raises(BenchmarkFileError, match=rf"bad\.csv: line {target + 2}, {message}"):
        read_episodes(path)
    out = tmp_path / "r"
    assert evaluate.main(["rescore", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("evaluate.py: error:") and "\n" not in err and str(path) in err
    assert not out.exists() or not any(out.iterdir())


def test_open_loop_errors_are_not_negative(tmp_path) -> None:
    rows = [open_row("a", i) for i in range(5)]
    rows[3]["fde_10_mm"] = -0.5
    path = write_episode_csv(tmp_path / "ol.csv", rows, OPENLOOP_COLUMNS)
    with pytest.raises(BenchmarkFileError, match=r"ol\.csv: line 5, fde_10_mm: '-0.5' is "
                                                 "negative"):
        read_episodes(path)


# ---------------------------------------------------------------------------------------- R11
HUGE_AGENT = textwrap.dedent("""
    import numpy as np
    from agents.predictive import PredictiveAgent


    class Huge(PredictiveAgent):
        horizon = 30

        def fit(self, dataset):
            return self

        def predict(self, receiver_history):
            return np.full((self.horizon, 3), 1e300)


    def make_agent():
        return Huge()
""")


def test_huge_predictions_stop_the_run_naming_agent_and_episode(tmp_path, capsys,
                                                                monkeypatch) -> None:
    """Predictions of 1e300 are finite but their errors are not: the run stops before it writes
    any file, naming the agent, the episode and the metric; an earlier run's files in --out stay
    as they were (its result and its own episode files), and nothing is written elsewhere."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "huge.py").write_text(HUGE_AGENT)
    data = generate_synthetic(n=12, ood_fraction=0.25, seed=0).save(tmp_path / "d.npz")
    out = tmp_path / "out"
    earlier = write_run(out, "huge")
    before = listing(tmp_path)
    argv = ["benchmark", "--agent", "huge.py:make_agent", "--name", "huge", "--tracks",
            "openloop", "--quick", "--no-progress", "--workers", "1", "--data", str(data),
            "--checkpoints", str(out / "ckpt"), "--out", str(out)]
    assert evaluate.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("evaluate.py: error: agent 'huge', openloop episode ")
    assert "rms_now_axis_mm: 'inf' is not a finite number or nan" in err
    after = listing(tmp_path)
    assert {k: v for k, v in after.items() if not k.startswith("out/ckpt")} == before
    assert load_results([earlier])[0][1]["agent"]["name"] == "huge"


def test_a_run_that_fails_half_way_leaves_no_result(run_dir, tmp_path) -> None:
    """A failure after the first episode file is written: the earlier result.json is gone, so
    the folder holds no result for the leaderboard to rank."""
    out = run_dir.parent
    bad_closed = closed_rows("mine")
    bad_closed[0]["steps"] = -1  # refused when the written file is read back
    source = AgentSource("mine", "plugin", "/x/mine.py", "make", spec="mine.py:make")
    run = BenchmarkRun(source, ("openloop", "closedloop"), protocol.BenchmarkSettings(True),
                       {"openloop": [open_row("mine", i, fold=0) for i in range(4)],
                        "closedloop": bad_closed},
                       fingerprints(("openloop", "closedloop")), {})
    with pytest.raises(BenchmarkFileError, match=r"closedloop_episodes\.csv: line 2, steps"):
        output.write_benchmark(run, out)
    assert not run_dir.exists()
    with pytest.raises(BenchmarkFileError, match=r"result\.json: no such file"):
        load_results([run_dir])


def test_leaderboard_refuses_a_result_beside_other_episode_files(tmp_path, capsys) -> None:
    mine = write_run(tmp_path / "a", "mine")
    other = write_run(tmp_path / "b", "mine", {"closedloop": closed_rows("mine", fail_every=2)})
    closed = tmp_path / "a" / "closedloop_episodes.csv"
    own = closed.read_bytes()
    # an earlier run's result.json beside a newer run's closed-loop file
    closed.write_bytes((other.parent / "closedloop_episodes.csv").read_bytes())
    with pytest.raises(LeaderboardError, match=rf"{mine}: field episodes\.closedloop\.sha256 is "
                                               ".* beside it hashes to"):
        load_results([mine])
    closed.write_bytes(own)
    assert load_results([mine])
    (tmp_path / "a" / "openloop_episodes.csv").unlink()
    with pytest.raises(LeaderboardError, match=r"field episodes\.openloop\.file: .* is missing"):
        load_results([mine])
    (tmp_path / "a" / "openloop_episodes.csv").symlink_to(other.parent / "benchmark.md")
    with pytest.raises(LeaderboardError, match=r"episodes\.openloop\.file: .*not a regular "
                                               "file"):
        load_results([mine])
    out = tmp_path / "lb"
    assert evaluate.main(["leaderboard", str(mine), "--out", str(out)]) == 2
    assert "episodes.openloop.file" in capsys.readouterr().err
    assert not out.exists() or not (out / "leaderboard.md").exists()


def test_leaderboard_ranks_at_most_max_results(run_dir) -> None:
    with pytest.raises(LeaderboardError, match=f"at most {leaderboard.MAX_RESULTS} are ranked"):
        load_results([run_dir] * (leaderboard.MAX_RESULTS + 1))


def test_check_rows_names_the_agent_and_the_episode() -> None:
    from handover_eval.benchmark.run import check_rows

    check_rows("closedloop", closed_rows("mine"))  # a run's own rows pass
    rows = closed_rows("mine")
    rows[1]["release_force"] = -2.0
    with pytest.raises(ValueError, match=r"agent 'mine', closedloop episode walker-id "
                                         r"walker-id-0001: release_force: '-2' is negative"):
        check_rows("closedloop", rows)
