"""The Ray backend (issue 15): the same tables as the process backend, retries, failures named.

Skipped when Ray is not importable (``pip install -e '.[test]'`` installs it). The table1 run
starts and stops its own local Ray instance, as the command does; the other tests share one
small instance (module fixture) to keep Ray's start-up out of every test.
"""

from __future__ import annotations

import csv
import os
import shutil
import sys
from dataclasses import asdict
from pathlib import Path

import pytest

ray = pytest.importorskip(
    "ray", reason="Ray is not installed: pip install -e '.[cluster]' (or '.[test]')"
)

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import evaluate  # noqa: E402
from handover_eval.act_folds import EXPORT_PREFIX  # noqa: E402
from handover_eval.backend import (  # noqa: E402
    WORKER_ENV,
    Backend,
    JobError,
    map_jobs,
    session,
)
from handover_eval.methods import METHODS  # noqa: E402

TIMING = {"fit_seconds", "fit_seconds_mean", "wall_s", "seconds"}


def _rows(path: Path) -> list[dict[str, str]]:
    """A CSV's rows without its wall-time columns (the only thing allowed to differ)."""
    with path.open(newline="") as fh:
        return [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def table1_runs(
    tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest
) -> dict[str, Path]:
    """``table1 --quick`` on Ray, Ray started and shut down by the command itself, beside the
    same run on processes (the session's shared run, tests/conftest.py). The Ray run starts from
    the process run's ACT export (made in the calling process on either backend, as a rerun
    finds it); every model, ACT's included, is trained on Ray."""
    assert not ray.is_initialized()
    proc = request.getfixturevalue("table1_quick") / "out"
    on_ray = tmp_path_factory.mktemp("table1") / "ray"
    (export,) = (proc / "checkpoints").glob(f"{EXPORT_PREFIX}*")
    shutil.copytree(export, on_ray / "checkpoints" / export.name)
    argv = ["table1", "--quick", "--no-progress", "--workers", "2", "--backend", "ray",
            "--out", str(on_ray)]
    assert evaluate.main(argv) == 0
    assert not ray.is_initialized()  # the command shut its local instance down
    return {"process": proc, "ray": on_ray}


@pytest.fixture(scope="module")
def ray_instance():
    """One small local Ray instance for the remaining tests (the commands reuse it, not stop it)."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": dict(WORKER_ENV)})
    # the job functions below live in this test module, which Ray workers cannot import by name
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield ray
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    ray.shutdown()


def test_table1_quick_same_tables_on_ray_and_processes(table1_runs: dict[str, Path],
                                                        capsys: pytest.CaptureFixture) -> None:
    proc, on_ray = table1_runs["process"], table1_runs["ray"]
    m = len(METHODS)  # every open-loop method, the constant-velocity predictor included
    for name, n in (
        ("table1_episodes.csv", m * 30),
        ("table1_folds.csv", m * 3),
        ("table1.csv", m),
    ):
        rows = _rows(on_ray / name)
        assert len(rows) == n
        assert rows == _rows(proc / name), name
    assert _rows(on_ray / "table1_folds.csv")[0]["checkpoint_reused"] == "False"  # trained on Ray


def test_sample_efficiency_quick_same_on_ray(
    tmp_path: Path, ray_instance, request: pytest.FixtureRequest
) -> None:
    """Ray's tables equal the shared process run's (tests/eval/conftest.py; same argv)."""
    argv = ["sample-efficiency", "--quick", "--no-progress", "--methods", "ours", "bc_mlp",
            "--ratios", "0.5", "1.0", "--backend", "ray", "--out", str(tmp_path / "ray")]
    assert evaluate.main(argv) == 0
    proc = request.getfixturevalue("sample_efficiency_quick") / "out"
    tables = [
        (_rows(out / "sample_efficiency_folds.csv"), _rows(out / "sample_efficiency.csv"))
        for out in (proc, tmp_path / "ray")
    ]
    assert len(tables[0][0]) == 2 * 2 * 3  # method x ratio x fold
    assert tables[0] == tables[1]


def test_closed_loop_quick_same_on_ray(
    tmp_path: Path, ray_instance, closed_loop_quick: Path
) -> None:
    """Ray's episodes equal those of the same agents in the shared process run
    (tests/eval/conftest.py), whose BC-MLP checkpoint the Ray run reuses, as a rerun does."""
    agents = ["reactive", "ours", "bc-mlp"]
    shutil.copytree(closed_loop_quick / "checkpoints", tmp_path / "checkpoints")
    argv = ["closed-loop", "--quick", "--no-progress", "--agents", *agents,
            "--checkpoints", str(tmp_path / "checkpoints"), "--bootstrap", "50",
            "--backend", "ray", "--out", str(tmp_path / "ray")]
    assert evaluate.main(argv) == 0
    on_ray = _rows(tmp_path / "ray" / "closed_loop_episodes.csv")
    proc = [r for r in _rows(closed_loop_quick / "out" / "closed_loop_episodes.csv")
            if r["agent"] in agents]
    assert len(proc) > 10 and {r["agent"] for r in proc} == set(agents)
    assert on_ray == proc


# ------------------------------------------------------------------------------- failures
def _flaky(folder: Path, job: int) -> int:
    """Fails on its first attempt (raises for job 0, kills its worker process for job 1); writes
    its result file and returns ``job**2`` on the retry. Other jobs succeed at once."""
    first = folder / f"attempted-{job}"
    if job in (0, 1) and not first.exists():
        first.touch()
        if job == 1:
            os._exit(3)  # the worker dies mid-task: Ray retries the task on another worker
        raise RuntimeError(f"transient failure of job {job}")
    (folder / f"result-{job}").write_text(str(job * job))
    return job * job


def _always_fails_on_2(folder: Path, job: int) -> int:
    if job == 2:
        (folder / "attempts-2").open("a").write("x")
        raise ValueError("job 2 cannot be done")
    (folder / f"result-{job}").write_text(str(job * job))
    return job * job


def test_ray_retries_a_raised_and_a_crashed_task_once(tmp_path: Path, ray_instance) -> None:
    with session(Backend("ray"), workers=2, log=None):
        assert map_jobs(_flaky, tmp_path, list(range(4)), progress=False) == [0, 1, 4, 9]
    assert (tmp_path / "attempted-0").exists() and (tmp_path / "attempted-1").exists()


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_a_job_failing_twice_is_named_and_the_others_kept(
    tmp_path: Path, backend: str, ray_instance
) -> None:
    with session(Backend(backend), workers=2, log=None), pytest.raises(
        JobError, match=r"folds: 1 of 4 job\(s\) failed"
    ) as err:
        map_jobs(_always_fails_on_2, tmp_path, list(range(4)), workers=2, progress=False,
                 desc="folds", label=lambda j: f"fold {j}")
    assert err.value.failed == {"fold 2": "ValueError: job 2 cannot be done"}
    assert "fold 2" in str(err.value) and "1 of 4 job(s) failed" in str(err.value)
    assert err.value.completed == {0: 0, 1: 1, 3: 9}
    assert [(tmp_path / f"result-{j}").read_text() for j in (0, 1, 3)] == ["0", "1", "9"]
    assert (tmp_path / "attempts-2").read_text() == "xx"  # tried, retried once, then given up


def test_act_fold_failing_on_ray_is_named_and_finished_checkpoints_stay(
    table1_runs: dict[str, Path], tmp_path: Path, ray_instance, capsys: pytest.CaptureFixture
) -> None:
    """ACT pre-training on Ray: one fold's export is missing; the other fold still trains and its
    checkpoint is complete on disk (a rerun reuses it); the error names the failed fold."""
    from handover_eval.act_folds import ACTJob, run_act_jobs
    from handover_eval.methods import COMPLETE, MethodOptions, build_agent

    export = next((table1_runs["ray"] / "checkpoints").glob("act-export-*"))
    config = asdict(build_agent("act", MethodOptions(quick=True)).config)
    jobs = [
        ACTJob("fold 0", config, tuple(range(20)), str(tmp_path / "ck0"), "{}", str(export)),
        ACTJob(
            "fold 1",
            config,
            tuple(range(20)),
            str(tmp_path / "ck1"),
            "{}",
            str(tmp_path / "missing"),
        ),
    ]
    with (
        session(Backend("ray"), workers=2, log=None),
        pytest.raises(JobError, match="fold 1") as err,
    ):
        run_act_jobs(jobs, workers=2, progress=False, log=None)
    assert (
        list(err.value.failed) == ["fold 1"]
        and "not a handover LeRobot export" in err.value.failed["fold 1"]
    )
    assert (tmp_path / "ck0" / COMPLETE).exists() and not (tmp_path / "ck1" / COMPLETE).exists()


def test_cli_without_ray_names_the_extra(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                         capsys: pytest.CaptureFixture) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    argv = ["table1", "--quick", "--no-progress", "--backend", "ray", "--out", str(tmp_path)]
    assert evaluate.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[cluster]" in err[0]


def test_ray_address_needs_the_ray_backend(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    argv = ["closed-loop", "--quick", "--ray-address", "auto", "--out", str(tmp_path)]
    assert evaluate.main(argv) == 2
    assert "--ray-address needs --backend ray" in capsys.readouterr().err
