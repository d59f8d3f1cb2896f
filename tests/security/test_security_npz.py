"""Issue 16 items 5 and 13, issue 20 item 9 (rate): bounded, validated ``.npz`` datasets."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from baselines_toy import toy_dataset
from crafted import lying_header_npy, many_members_npz, npz_members, write_npz

from handover_env.data import DatasetError, HandoverDataset
from handover_env.data import npz as npz_io
from handover_env.data.dataset import MAX_RATE_HZ, MIN_RATE_HZ
from handover_env.data.limits import MAX_ABS_COORD_M
from handover_eval.cli.data import main


@pytest.fixture()
def members():
    return npz_members(toy_dataset(n=4, length=40, seed=0))


# ---------------------------------------------------------------------- item 5: sizes
def test_unused_members_are_never_read(tmp_path: Path, members) -> None:
    """An extra member whose header declares 16 GB used to be decompressed and allocated on load."""
    path = write_npz(tmp_path / "d.npz", {**members, "junk": lying_header_npy((10**9, 2))})
    ds = HandoverDataset.load(path)
    assert len(ds) == 4 and ds.n_frames == int(members["lengths"].sum())


def test_a_used_member_whose_header_lies_is_refused_before_allocation(
    tmp_path: Path, members
) -> None:
    path = write_npz(tmp_path / "d.npz", {**members, "giver_xyz": lying_header_npy((10**9, 3))})
    with pytest.raises(
        DatasetError,
        match=r"d\.npz: member giver_xyz: its header declares shape "
        r"\(1000000000, 3\) of float64 \(24,000,000,000 bytes\)",
    ):
        HandoverDataset.load(path)


def test_declared_member_sizes_are_bounded(tmp_path: Path, members, monkeypatch) -> None:
    path = write_npz(tmp_path / "d.npz", members)
    declared = 128 + members["giver_xyz"].nbytes  # the zip entry: .npy header + data
    monkeypatch.setattr(npz_io, "MAX_NPZ_MEMBER_BYTES", 1000)
    with pytest.raises(
        DatasetError,
        match=rf"d\.npz: member giver_xyz declares {declared:,} bytes \(at most 1,000\)",
    ):
        HandoverDataset.load(path)
    monkeypatch.setattr(npz_io, "MAX_NPZ_MEMBER_BYTES", 10**9)
    monkeypatch.setattr(npz_io, "MAX_NPZ_TOTAL_BYTES", 3000)
    with pytest.raises(DatasetError, match="the members declare more than 3,000 bytes in all"):
        HandoverDataset.load(path)


def test_archive_directory_size_is_bounded(tmp_path: Path) -> None:
    path = many_members_npz(tmp_path / "d.npz", declared=60_000)
    with pytest.raises(
        DatasetError, match=r"d\.npz: the archive lists 60,000 members \(at most 64\)"
    ):
        HandoverDataset.load(path)


def test_object_members_are_refused(tmp_path: Path, members) -> None:
    header = lying_header_npy((1,), dtype="|O", data=b"")
    path = write_npz(tmp_path / "d.npz", {**members, "source_id": header})
    with pytest.raises(DatasetError, match="member source_id: object dtype"):
        HandoverDataset.load(path)


# ---------------------------------------------------------------------- item 13: content
@pytest.mark.parametrize(
    "change, message",
    [
        (
            {"format_version": np.array([1, 1])},
            r"format_version must be a single integer, got dtype int64 shape \(2,\)",
        ),
        (
            {"rate_hz": np.array([30.0, 30.0])},
            r"rate_hz must be a single number, got dtype float64 shape \(2,\)",
        ),
        (
            {"format_version": np.array(1.9)},
            r"format_version must be a single integer, got dtype float64",
        ),
        ({"format_version": np.array(2)}, "format version 2, this code reads 1"),
        ("strings_ood", r"is_ood must be 4 booleans, got dtype <U5"),
        ("zero_quat", r"episode 'toy_001': object_quat has a zero-norm .*quaternion at frame 3"),
        (
            "huge_coordinate",
            rf"episode 'toy_000': giver_xyz reaches 1e\+308 m, outside the "
            rf"\+-{MAX_ABS_COORD_M:g} m",
        ),
        ("no_episodes", "holds no episodes"),
        ({"source_id": np.array([1, 2, 3, 4])}, "source_id must be 4 strings"),
        (
            {"receiver_xy": np.zeros((3, 2))},
            r"receiver_xy has dtype float64 shape \(3, 2\), expected floats",
        ),
    ],
    ids=[
        "2-element-version",
        "2-element-rate",
        "version-1.9",
        "version-2",
        "is_ood-strings",
        "zero-quaternion",
        "1e308-metres",
        "0-episodes",
        "int-ids",
        "short-array",
    ],
)
def test_malformed_content_is_refused_with_its_reason(
    tmp_path: Path, members, change, message: str
) -> None:
    m = dict(members)
    if change == "strings_ood":
        m["is_ood"] = np.array(["False", "False", "False", "True"])
    elif change == "zero_quat":
        q = m["object_quat"].copy()
        q[int(m["lengths"][0]) + 3] = 0.0
        m["object_quat"] = q
    elif change == "huge_coordinate":
        g = m["giver_xyz"].copy()
        g[5, 0] = 1e308
        m["giver_xyz"] = g
    elif change == "no_episodes":
        m.update(
            lengths=np.zeros(0, dtype=np.int64),
            is_ood=np.zeros(0, bool),
            source_id=np.array([], dtype="<U1"),
            **{
                k: m[k][:0]
                for k in ("receiver_xy", "receiver_hand_xyz", "giver_xyz", "object_quat")
            },
        )
    else:
        m.update(change)
    path = write_npz(tmp_path / "bad.npz", m)
    with pytest.raises(DatasetError, match=rf"bad\.npz: .*{message}"):
        HandoverDataset.load(path)


def test_a_file_of_1e308_metres_does_not_reach_training(tmp_path: Path, members, capsys) -> None:
    """Item 13: such a file used to train to loss inf, exit 0 and save the model."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from handover_eval.cli import train

    g = members["giver_xyz"].copy()
    g[:, 0] = 1e308
    path = write_npz(tmp_path / "far.npz", {**members, "giver_xyz": g})
    assert (
        train.main(["bc-mlp", "--smoke", "--data", str(path), "--out", str(tmp_path / "run")]) == 2
    )
    assert "far.npz: episode 'toy_000': giver_xyz reaches 1e+308 m" in capsys.readouterr().err
    assert not (tmp_path / "run" / "model.safetensors").exists()


def test_compare_says_when_a_side_has_no_episodes_of_a_kind(tmp_path: Path, capsys) -> None:
    """Item 13: compare printed an empty table when one side had no ID episodes."""
    a = tmp_path / "a.npz"
    main(["synth", "--n", "12", "--ood-fraction", "0.25", "--seed", "1", str(a)])
    ood_only = HandoverDataset.load(a)
    ood_only = ood_only.subset(np.flatnonzero(ood_only.ood_mask))
    b = ood_only.save(tmp_path / "b.npz")
    capsys.readouterr()
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "[id episodes]\nnothing to compare: B has no ID episodes" in out
    assert out.count("rel. diff") == 2  # the all and ood tables are still printed
    assert main(["compare", str(a), str(b), "--subset", "id"]) == 2
    assert "no subset of ['id'] has episodes on both sides" in capsys.readouterr().err


# ---------------------------------------------------------------------- issue 20 item 9: rate
@pytest.mark.parametrize("rate", [1e-300, 0.5, 1e6, np.inf, -30.0], ids=str)
def test_an_implausible_rate_is_refused_naming_file_and_field(
    tmp_path: Path, members, rate: float, capsys
) -> None:
    """``rate_hz = 1e-300`` was accepted: every time step became 1e300 s."""
    path = write_npz(tmp_path / "slow.npz", {**members, "rate_hz": np.array(rate)})
    shown = re.escape(f"{rate:g}")
    bounds = rf"{MIN_RATE_HZ:g} \.\. {MAX_RATE_HZ:g} Hz"
    message = rf"slow\.npz: rate_hz is {shown} Hz, outside the {bounds}"
    with pytest.raises(DatasetError, match=message):
        HandoverDataset.load(path)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"slow.npz: rate_hz is {rate:g} Hz" in err
    good = HandoverDataset.load(write_npz(tmp_path / "ok.npz", members))
    with pytest.raises(DatasetError, match=rf"rate_hz is {shown} Hz, outside"):
        HandoverDataset(good.episodes, rate_hz=rate)


@pytest.mark.parametrize("rate", [MIN_RATE_HZ, 30.0, 120.0, MAX_RATE_HZ])
def test_plausible_rates_still_load(tmp_path: Path, members, rate: float) -> None:
    path = write_npz(tmp_path / "d.npz", {**members, "rate_hz": np.array(rate)})
    ds = HandoverDataset.load(path)
    assert ds.rate_hz == rate and ds.dt == pytest.approx(1.0 / rate)
