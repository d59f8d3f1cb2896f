"""The presentation check (handover_eval/closedloop/presentation.py): the table's counts against
hand-made rows, the safe reading of a run's episodes, and, on the development copy of the
dataset, the giver replay presenting as the recorded givers did (the frames of both sides agree)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import evaluate
from handover_eval.closedloop.presentation import (
    QUANTITIES,
    PresentationError,
    presentation_table,
    read_episode_rows,
)
from handover_eval.reporting import read_csv, write_csv

DATA = Path(__file__).resolve().parents[2] / "../shared/data/dynamic_handover_dataset/whole_motions"
RANGES = {m: {"low": 0.0, "high": 1.0, "median": 0.5, "n": 100} for m, *_ in QUANTITIES.values()}


def _row(agent: str, kind: str, values: dict[str, float], is_ood: bool = False) -> dict:
    row = {"agent": agent, "set": kind, "is_ood": str(is_ood)}
    row.update({c: "0.5" for c in QUANTITIES})
    row.update({c: str(v) for c, v in values.items()})
    return row


def test_the_table_counts_grasps_below_and_above_the_recorded_range() -> None:
    rows = [
        _row("a", "replay", {"transfer_object_up": -0.1}),
        _row("a", "replay", {"transfer_object_up": 1.5, "transfer_object_speed": 2.0}),
        _row("a", "replay", {"transfer_robot_jerk": 9.0}),  # jerk alone: not 'outside'
        _row("a", "replay", {}, is_ood=True),
        _row("a", "replay", {"transfer_object_fwd": float("nan")}),  # no grasp: not counted
        _row("b", "id", {"transfer_object_lat": -2.0}),
    ]
    table = {(t["agent"], t["set"]): t for t in presentation_table(rows, RANGES)}
    assert set(table) == {("a", "replay-id"), ("a", "replay-ood"), ("a", "replay-all"),
                          ("b", "walker-id")}
    t = table[("a", "replay-id")]
    assert t["n"] == 3
    assert t["transfer_object_up_below"] == pytest.approx(1 / 3)
    assert t["transfer_object_up_above"] == pytest.approx(1 / 3)
    assert t["transfer_object_speed_above"] == pytest.approx(1 / 3)
    assert t["transfer_robot_jerk_above"] == pytest.approx(1 / 3)
    assert t["transfer_object_up_median"] == pytest.approx(0.5)
    assert t["any_outside"] == pytest.approx(2 / 3)
    assert table[("a", "replay-all")]["n"] == 4 and table[("a", "replay-ood")]["any_outside"] == 0
    assert table[("b", "walker-id")]["transfer_object_lat_below"] == 1.0


def test_reading_a_run_refuses_links_out_and_files_of_another_kind(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    with pytest.raises(PresentationError, match="closed_loop_episodes.csv"):
        read_episode_rows(run)  # no file
    outside = tmp_path / "elsewhere.csv"
    write_csv([_row("a", "id", {})], outside)
    os.symlink(outside, run / "closed_loop_episodes.csv")
    with pytest.raises(PresentationError, match="outside|link"):
        read_episode_rows(run)
    (run / "closed_loop_episodes.csv").unlink()
    write_csv([{"agent": "a", "set": "id", "is_ood": "False"}], run / "closed_loop_episodes.csv")
    with pytest.raises(PresentationError, match="transfer_object_fwd"):
        read_episode_rows(run)
    (run / "closed_loop_episodes.csv").write_bytes(b"agent,set\n\xff\xfe,x\n")
    with pytest.raises(PresentationError, match="UTF-8"):
        read_episode_rows(run)
    write_csv([_row("a", "id", {})], run / "closed_loop_episodes.csv")
    assert read_episode_rows(run)[0]["agent"] == "a"


def test_the_command_names_a_missing_data_folder(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    assert evaluate.main(["presentation", str(tmp_path), "--data", str(tmp_path / "no")]) == 2
    assert "--data" in capsys.readouterr().err


@pytest.mark.skipif(not DATA.is_dir(), reason="public dataset copy not found at ../shared/data")
def test_the_giver_replay_presents_as_the_recorded_givers(tmp_path: Path) -> None:
    """The giver replay moves the bottle along the recorded giver's path to the replayed person:
    its bottle at the grasp sits where the recorded bottle sat at the transfer, relative to the
    pelvis in the walking frame, and moves as fast, so the two sides' frames agree. (Its robot
    jerk is the controller's tracking, not the giver's: not compared here.)"""
    out = tmp_path / "run"
    assert evaluate.main(["closed-loop", "--quick", "--agents", "giver-replay", "--sets",
                          "replay", "--replay-data", str(DATA), "--out", str(out),
                          "--no-progress"]) == 0
    assert evaluate.main(["presentation", str(out), "--data", str(DATA), "--no-progress"]) == 0
    rows = {r["set"]: r for r in read_csv(out / "presentation.csv")}
    t = rows["replay-all"]
    assert int(t["n"]) >= 20
    assert float(t["transfer_object_up_median"]) == pytest.approx(0.422, abs=0.03)
    assert float(t["transfer_object_speed_median"]) == pytest.approx(0.54, abs=0.08)
    assert float(t["any_outside"]) <= 0.35  # a recorded giver: 10 % per quantity by construction
    assert (out / "presentation.md").read_text().startswith("# Presentation at the grasp")
    assert (out / "presentation.png").stat().st_size > 10_000
