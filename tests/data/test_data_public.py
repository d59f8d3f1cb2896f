"""Safe loading of the public dataset: malicious and malformed pickles, folders, the real copy."""

from __future__ import annotations

import os
import pickle
import time
from pathlib import Path

import numpy as np
import pytest

from handover_env.data import DatasetError, UnsafePickleError, load_public_dataset
from handover_env.data.public import LoadReport, canonical_quaternions, load_public_file

REAL = (
    Path(__file__).resolve().parents[2].parent
    / "shared"
    / "data"
    / "dynamic_handover_dataset"
    / "whole_motions"
)


def _record(t: int = 40, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    quat = rng.standard_normal((t, 4))
    return {
        "pose_receiver": rng.standard_normal((t, 34, 3)),
        "pose_giver": rng.standard_normal((t, 34, 3)),
        "pose_object": rng.standard_normal((t, 3)),
        "quat_object": quat / np.linalg.norm(quat, axis=1, keepdims=True),
    }


def _write(folder: Path, name: str, obj: object) -> Path:
    path = folder / name
    path.write_bytes(pickle.dumps(obj, protocol=4))
    return path


class _Exploit:
    """Unpickling this would run os.system (creating the marker file)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_good_file_maps_to_canonical_episode(tmp_path: Path) -> None:
    rec = _record(50)
    ep = load_public_file(_write(tmp_path, "motion_normal_3.pkl", rec))
    assert ep.source_id == "motion_normal_3" and not ep.is_ood and ep.length == 50
    np.testing.assert_array_equal(ep.receiver_xy, rec["pose_receiver"][:, 0, :2])
    np.testing.assert_array_equal(ep.receiver_hand_xyz, rec["pose_receiver"][:, 15])
    np.testing.assert_array_equal(ep.giver_xyz, rec["pose_object"])
    assert np.allclose(np.abs(np.einsum("ij,ij->i", ep.object_quat, rec["quat_object"])), 1.0)
    assert load_public_file(_write(tmp_path, "motion_variation_0.pkl", rec)).is_ood


def test_malicious_pickle_is_refused_without_side_effect(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    rec = _record()
    rec["payload"] = _Exploit(marker)
    path = _write(tmp_path, "motion_normal_0.pkl", rec)
    assert b"system" in path.read_bytes()  # the payload is really in the file
    with pytest.raises(UnsafePickleError, match=r"motion_normal_0\.pkl.*(posix|os|nt)\.system"):
        load_public_file(path)
    with pytest.raises(UnsafePickleError, match="motion_normal_0.pkl"):
        load_public_dataset(tmp_path, progress=False)
    assert not marker.exists()


def test_other_globals_are_refused(tmp_path: Path) -> None:
    path = _write(tmp_path, "motion_normal_1.pkl", {"x": Path("/")})
    with pytest.raises(UnsafePickleError, match="pathlib"):
        load_public_file(path)


@pytest.mark.parametrize(
    "name, content, match",
    [
        ("empty", b"", "empty file"),
        ("truncated", pickle.dumps(_record(), protocol=4)[:500], "truncated"),
        ("garbage", b"this is not a pickle at all", "not a readable pickle"),
    ],
)
def test_unreadable_files(tmp_path: Path, name: str, content: bytes, match: str) -> None:
    path = tmp_path / "motion_normal_7.pkl"
    path.write_bytes(content)
    with pytest.raises(DatasetError, match=rf"motion_normal_7\.pkl.*{match}"):
        load_public_file(path)


def _mutate(kind: str) -> dict:
    rec = _record()
    if kind == "missing_key":
        del rec["quat_object"]
    elif kind == "nan":
        rec["pose_object"][5, 1] = np.nan
    elif kind == "inf":
        rec["pose_receiver"][3, 0, 0] = np.inf
    elif kind == "shape":
        rec["pose_receiver"] = rec["pose_receiver"][:, :20]
    elif kind == "length":
        rec["pose_object"] = rec["pose_object"][:-3]
    elif kind == "dtype":
        rec["pose_object"] = rec["pose_object"].astype(str)
    elif kind == "not_dict":
        return [rec["pose_object"]]  # type: ignore[return-value]
    elif kind == "zero_quat":
        rec["quat_object"][2] = 0.0
    return rec


@pytest.mark.parametrize(
    "kind, match",
    [
        ("missing_key", r"missing key\(s\) \['quat_object'\]"),
        ("nan", "pose_object has 1 NaN/inf value"),
        ("inf", "pose_receiver has 1 NaN/inf"),
        ("shape", r"pose_receiver has shape \(40, 20, 3\), expected \(T, 34, 3\)"),
        ("length", "disagree in length"),
        ("dtype", "dtype <U"),
        ("not_dict", "expected a dict"),
        ("zero_quat", "zero-norm"),
    ],
)
def test_invalid_content_gets_its_own_error(tmp_path: Path, kind: str, match: str) -> None:
    path = _write(tmp_path, "motion_variation_2.pkl", _mutate(kind))
    with pytest.raises(DatasetError, match=rf"motion_variation_2\.pkl: .*{match}"):
        load_public_file(path)


def test_folder_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no public-dataset folder"):
        load_public_dataset(tmp_path / "absent", progress=False)
    (tmp_path / "readme.txt").write_text("nothing here")
    with pytest.raises(DatasetError, match="no motion_normal_<i>.pkl"):
        load_public_dataset(tmp_path, progress=False)


def test_skip_bad_reports_and_natural_order(tmp_path: Path) -> None:
    for i in (10, 2, 1):
        _write(tmp_path, f"motion_normal_{i}.pkl", _record(30 + i, seed=i))
    _write(tmp_path, "motion_variation_0.pkl", _record(45))
    (tmp_path / "motion_normal_5.pkl").write_bytes(b"")
    _write(tmp_path, "motion_variation_1.pkl", _mutate("nan"))
    with pytest.raises(DatasetError, match="motion_normal_5.pkl"):
        load_public_dataset(tmp_path, progress=False)
    report, seen = LoadReport(), []
    ds = load_public_dataset(
        tmp_path, skip_bad=True, progress=False, report=report, on_skip=lambda *a: seen.append(a)
    )
    assert [ep.source_id for ep in ds] == [
        "motion_normal_1",
        "motion_normal_2",
        "motion_normal_10",
        "motion_variation_0",
    ]
    assert report.loaded == 4 and [name for name, _ in report.skipped] == [
        "motion_normal_5.pkl",
        "motion_variation_1.pkl",
    ]
    assert "empty" in report.skipped[0][1] and "NaN" in report.skipped[1][1] and len(seen) == 2
    assert "skipped motion_normal_5.pkl" in report.summary()
    with pytest.warns(UserWarning, match="skipping"):
        load_public_dataset(tmp_path, skip_bad=True, progress=False)


def test_all_bad_is_an_error(tmp_path: Path) -> None:
    (tmp_path / "motion_normal_0.pkl").write_bytes(b"")
    with pytest.raises(DatasetError, match="none of the 1"):
        load_public_dataset(tmp_path, skip_bad=True, progress=False, on_skip=lambda *a: None)


def test_canonical_quaternions_are_sign_continuous() -> None:
    rng = np.random.default_rng(0)
    q = np.cumsum(rng.standard_normal((100, 4)) * 0.05, axis=0) + np.array([-1.0, 0, 0, 0])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    flipped = q * np.where(rng.random(100) < 0.3, -1.0, 1.0)[:, None]
    out = canonical_quaternions(flipped * 2.0)
    assert out[0, 0] >= 0 and np.allclose(np.linalg.norm(out, axis=1), 1.0)
    assert np.all(np.einsum("ij,ij->i", out[1:], out[:-1]) > 0)
    assert np.allclose(np.abs(np.einsum("ij,ij->i", out, q)), 1.0)


@pytest.mark.skipif(not REAL.is_dir(), reason="public dataset copy not found at ../shared/data")
def test_real_copy_loads_completely() -> None:
    start = time.perf_counter()
    ds = load_public_dataset(REAL, progress=False)
    elapsed = time.perf_counter() - start
    mask = ds.ood_mask
    assert len(ds) == 875 and int((~mask).sum()) == 800 and int(mask.sum()) == 75
    assert ds.n_frames == 112_566 and ds.lengths.min() == 69 and ds.lengths.max() == 287
    assert ds[0].source_id == "motion_normal_0" and ds[800].source_id == "motion_variation_0"
    assert all(np.all(ep.object_quat[0, 0] >= 0) for ep in ds)
    assert elapsed < 60
