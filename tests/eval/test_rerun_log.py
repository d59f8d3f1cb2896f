"""``evaluate.py closed-loop --rerun FILE.rrd``: the logged episode, read back with Rerun's own
reader, is the run's episode (the same steps, outcome, release force and handover time as its
CSV row) with the person's skeleton and body, the TCP, the bottle, the wrist force and the
outcome events at every step; a bad path is refused before the run."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from handover_eval.cli import evaluate
from handover_eval.reporting import read_csv

rd = pytest.importorskip("rerun.dataframe")
RATE_HZ = 30.0


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rerun")
    assert evaluate.main(["closed-loop", "--quick", "--agents", "reactive", "--walkers", "1",
                          "--sets", "id", "--workers", "1", "--no-progress",
                          "--out", str(tmp / "cl"), "--checkpoints", str(tmp / "ckpt"),
                          "--rerun", str(tmp / "episode.rrd")]) == 0
    row = read_csv(tmp / "cl" / "closed_loop_episodes.csv")[0]
    table = rd.load_recording(str(tmp / "episode.rrd")).view(
        index="sim_time", contents="/**").select().read_all()
    return row, table


def _column(table, name: str) -> list:
    return table.column(name).to_pylist()


def test_the_recording_is_the_runs_episode(logged) -> None:
    row, table = logged
    assert (row["agent"], row["set"], row["receiver"]) == ("reactive", "id", "id-0000")
    steps = int(row["steps"])
    assert table.num_rows == steps
    times = [t.total_seconds() for t in _column(table, "sim_time")]
    assert times == pytest.approx([(k + 1) / RATE_HZ for k in range(steps)], abs=1e-6)
    events = [e[0] for e in _column(table, "/events:TextLog:text") if e]
    outcome = [e for e in events if e.startswith("outcome: ")]
    assert len(outcome) == 1 and outcome[0].startswith(f"outcome: {row['outcome']}")
    if row["outcome"] == "success":
        shown = re.search(r"handover time ([0-9.]+) s", outcome[0])
        assert shown and abs(float(shown[1]) - float(row["handover_time"])) <= 0.005 + 1e-9
        released = [e for e in events if e.startswith("gripper released")]
        shown = re.search(r"wrist force ([0-9.]+) N", released[0])
        assert shown and abs(float(shown[1]) - float(row["release_force"])) <= 0.05 + 1e-9
        assert events.index("reach onset") < events.index(
            "grasp: the person's hand holds the bottle") < events.index(released[0]) < \
            events.index(outcome[0])
    force = [f[0] for f in _column(table, "/wrist/force:Scalars:scalars")]
    assert len(force) == steps and all(math.isfinite(f) and f >= 0 for f in force)
    assert max(force) <= float(row["peak_wrist_force"]) + 1e-9  # the peak is over 200 Hz ticks
    threshold = {f[0] for f in _column(table, "/wrist/release_threshold:Scalars:scalars")}
    assert threshold == {float(row["f_r"])}


def test_every_step_has_the_skeleton_the_tcp_and_the_bottle(logged) -> None:
    _, table = logged
    for name, shape in (("/world/person/joints:Points3D:positions", (14, 3)),
                        ("/world/robot/tcp:Points3D:positions", (1, 3)),
                        ("/world/bottle:Points3D:positions", (1, 3))):
        values = _column(table, name)
        assert all(v is not None and np.asarray(v).shape == shape for v in values), name
    bones = _column(table, "/world/person/bones:LineStrips3D:strips")
    assert all(len(b) == 13 for b in bones)  # 12 parent links and the hand's grip
    body = _column(table, "/world/person/body:LineStrips3D:strips")
    assert all(len(b) == 17 for b in body)  # the collision capsules (the skull is a sphere)
    joints = np.asarray(_column(table, "/world/person/joints:Points3D:positions"), dtype=float)
    bottle = np.asarray(_column(table, "/world/bottle:Points3D:positions"), dtype=float)
    assert np.all(np.isfinite(joints)) and np.all(np.isfinite(bottle))
    assert joints[-1, 0, 0] < joints[0, 0, 0]  # the person walks towards -x


@pytest.mark.parametrize("name, message", [
    ("episode.txt", r"--rerun must name a \.rrd file"),
    ("missing/episode.rrd", r"the folder .* does not exist"),
])
def test_a_bad_rerun_path_is_refused_before_the_run(tmp_path, capsys, name, message) -> None:
    assert evaluate.main(["closed-loop", "--quick", "--agents", "reactive", "--walkers", "1",
                          "--sets", "id", "--workers", "1", "--no-progress",
                          "--out", str(tmp_path / "cl"), "--rerun", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err) and err.startswith("evaluate.py: error: --rerun"), err
    assert not (tmp_path / "cl" / "closed_loop_episodes.csv").exists()
