"""The canonical HandoverDataset: validation, npz round-trip, stratified k-fold, subsampling."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from handover_env.data import DatasetError, Episode, HandoverDataset
from handover_env.person.demos import load_any
from handover_env.person.synthetic import generate_synthetic


@pytest.fixture(scope="module")
def small() -> HandoverDataset:
    return generate_synthetic(40, ood_fraction=0.25, seed=2)


def _episode(t: int = 10, source: str = "e", ood: bool = False, **override) -> Episode:
    fields = {
        "receiver_xy": np.zeros((t, 2)),
        "receiver_hand_xyz": np.zeros((t, 3)),
        "giver_xyz": np.zeros((t, 3)),
        "object_quat": np.tile([1.0, 0, 0, 0], (t, 1)),
    }
    fields.update(override)
    return Episode(**fields, is_ood=ood, source_id=source)


def test_episode_validation() -> None:
    with pytest.raises(DatasetError, match="receiver_xy must have shape"):
        _episode(receiver_xy=np.zeros((10, 3)))
    with pytest.raises(DatasetError, match="NaN"):
        _episode(giver_xyz=np.full((10, 3), np.nan))
    with pytest.raises(DatasetError, match="disagree in length"):
        _episode(giver_xyz=np.zeros((9, 3)))
    ep = _episode()
    with pytest.raises(ValueError, match="read-only"):
        ep.receiver_xy[0, 0] = 1.0  # arrays are read-only


@pytest.mark.parametrize(
    "bad",
    [
        np.full((10, 2), "1.0"),  # strings that float() would parse
        np.zeros((10, 2), dtype=object),
        np.zeros((10, 2), dtype=bool),
        np.zeros((10, 2), dtype=complex),
    ],
    ids=["str", "object", "bool", "complex"],
)
def test_episode_refuses_non_numeric_arrays(bad: np.ndarray) -> None:
    with pytest.raises(DatasetError, match=r"receiver_xy must be a real numeric array, got dtype"):
        _episode(receiver_xy=bad)
    assert _episode(receiver_xy=np.zeros((10, 2), dtype=np.int16)).receiver_xy.dtype == np.float64


def test_npz_round_trip(tmp_path: Path, small: HandoverDataset) -> None:
    path = small.save(tmp_path / "demo.npz")
    back = HandoverDataset.load(path)
    assert len(back) == len(small) and back.rate_hz == small.rate_hz and back.name == small.name
    for a, b in zip(small, back):
        assert a.source_id == b.source_id and a.is_ood == b.is_ood
        for name in ("receiver_xy", "receiver_hand_xyz", "giver_xyz", "object_quat"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert load_any(path).n_frames == small.n_frames
    assert not list(tmp_path.glob("*.tmp.npz"))


def test_load_errors(tmp_path: Path, small: HandoverDataset) -> None:
    with pytest.raises(FileNotFoundError, match="no dataset file at"):
        HandoverDataset.load(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(DatasetError, match=r"bad\.npz: not a readable"):
        HandoverDataset.load(bad)
    path = small.save(tmp_path / "v.npz")
    with np.load(path) as z:
        content = dict(z)
    content["format_version"] = np.array(99)
    np.savez(tmp_path / "future.npz", **content)
    with pytest.raises(DatasetError, match="format version 99"):
        HandoverDataset.load(tmp_path / "future.npz")
    del content["giver_xyz"]
    np.savez(tmp_path / "partial.npz", **content)
    with pytest.raises(DatasetError, match="missing keys"):
        HandoverDataset.load(tmp_path / "partial.npz")
    (tmp_path / "x.txt").write_text("x")
    with pytest.raises(DatasetError, match=r"expected a \.npz"):
        load_any(tmp_path / "x.txt")
    with pytest.raises(FileNotFoundError, match=r"no dataset at .*\(expected a \.npz file"):
        load_any(tmp_path / "nothing_here")


def test_stratified_kfold(small: HandoverDataset) -> None:
    folds = small.stratified_kfold(5, seed=0)
    tests = np.concatenate([test for _, test in folds])
    assert sorted(tests.tolist()) == list(range(len(small)))  # test sets partition the data
    mask = small.ood_mask
    for train, test in folds:
        assert not set(train) & set(test) and len(train) + len(test) == len(small)
        assert mask[test].sum() == 2 and (~mask[test]).sum() == 6  # 10 OOD / 30 ID over 5 folds
    again = small.stratified_kfold(5, seed=0)
    other = small.stratified_kfold(5, seed=1)
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(folds, again))
    assert any(not np.array_equal(a[1], b[1]) for a, b in zip(folds, other))
    with pytest.raises(ValueError, match="only 10 OOD"):
        small.stratified_kfold(11)
    with pytest.raises(ValueError, match="k must be an integer >= 2"):
        small.stratified_kfold(1)


def test_subsample(small: HandoverDataset) -> None:
    half = small.subsample(0.5, seed=0)
    assert len(half) == 20 and int(half.ood_mask.sum()) == 5
    ids = {ep.source_id for ep in half}
    assert ids <= {ep.source_id for ep in small}
    assert {ep.source_id for ep in small.subsample(0.5, seed=0)} == ids
    assert len(small.subsample(0.01)) == 2  # at least one of each kind
    with pytest.raises(ValueError, match=r"ratio must be in \(0, 1\]"):
        small.subsample(0.0)


def test_subset_and_properties(small: HandoverDataset) -> None:
    sub = small.subset([3, 0])
    assert [ep.source_id for ep in sub] == [small[3].source_id, small[0].source_id]
    assert small.n_frames == int(small.lengths.sum()) and small.dt == pytest.approx(1 / 30)
    with pytest.raises(IndexError, match="index out of range for a dataset of 40 episodes"):
        small.subset([len(small)])
    with pytest.raises(DatasetError, match="empty"):
        HandoverDataset([]).save("/tmp/never_written.npz")
