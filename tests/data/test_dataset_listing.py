"""Issue 16 item 14: every entry named like a dataset file is loaded or refused by name, never
skipped silently."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from crafted import write_good_pickle

from handover_env.data import DatasetError, load_public_dataset
from handover_env.data.public import LoadReport, list_public_files


@pytest.fixture()
def folder(tmp_path: Path) -> Path:
    """Two good files and one bad entry of every kind the issue lists."""
    pub = tmp_path / "pub"
    pub.mkdir()
    write_good_pickle(pub / "motion_normal_0.pkl")
    write_good_pickle(pub / "motion_variation_0.pkl", seed=1)
    (pub / "motion_normal_1.pkl").symlink_to(pub / "motion_normal_1.pkl")  # a loop
    (pub / "motion_normal_2.pkl").symlink_to(pub / "absent.pkl")  # dangling
    os.mkfifo(pub / "motion_normal_3.pkl")
    (pub / "motion_normal_4.pkl").mkdir()
    write_good_pickle(pub / "motion_normal_0.pkl\n")  # trailing newline: a duplicate of episode 0
    write_good_pickle(pub / "motion_normal_\u0661.pkl")  # ARABIC-INDIC DIGIT ONE: a duplicate of 1
    write_good_pickle(pub / "motion_normal_01.pkl")  # leading zero: another duplicate of 1
    outside = write_good_pickle(tmp_path / "outside.pkl")
    (pub / "motion_variation_1.pkl").symlink_to(outside)  # out of the folder
    (pub / "README.md").write_text("not a dataset file")  # ignored: not named like one
    return pub


REASONS = {
    "motion_normal_1.pkl": "symbolic link loop",
    "motion_normal_2.pkl": "dangling symbolic link",
    "motion_normal_3.pkl": "not a regular file",
    "motion_normal_4.pkl": "a folder, not a file",
    "motion_variation_1.pkl": "outside the dataset folder",
    "'motion_normal_0.pkl\\n'": "not a public-dataset file name",
    "motion_normal_\u0661.pkl": "not a public-dataset file name",
    "motion_normal_01.pkl": "not a public-dataset file name",
}


def test_every_bad_entry_is_reported_by_name(folder: Path) -> None:
    report = LoadReport()
    ds = load_public_dataset(
        folder, skip_bad=True, progress=False, report=report, on_skip=lambda *a: None
    )
    assert [ep.source_id for ep in ds] == ["motion_normal_0", "motion_variation_0"]
    assert len({ep.source_id for ep in ds}) == len(ds)  # no duplicate episode ids
    skipped = dict(report.skipped)
    assert set(skipped) == set(REASONS), sorted(skipped)
    for name, reason in REASONS.items():
        assert reason in skipped[name], (name, skipped[name])
    assert report.summary().startswith("loaded 2 file(s), skipped 8")
    assert (
        len(report.summary().splitlines()) == 1 + 8
    )  # the name with a newline is quoted, one line each


def test_without_skip_bad_the_first_bad_entry_is_an_error(folder: Path) -> None:
    with pytest.raises(DatasetError, match=r"motion_normal_1\.pkl: symbolic link loop"):
        load_public_dataset(folder, progress=False)


def test_links_inside_the_folder_still_load(tmp_path: Path) -> None:
    pub = tmp_path / "pub"
    (pub / "store").mkdir(parents=True)
    write_good_pickle(pub / "store" / "recording.pkl")
    (pub / "motion_normal_0.pkl").symlink_to(pub / "store" / "recording.pkl")
    assert [p.name for p in list_public_files(pub)] == ["motion_normal_0.pkl"]
    assert len(load_public_dataset(pub, progress=False)) == 1
