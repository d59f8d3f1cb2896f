"""Issue 16 items 4-6: crafted pickles end with a named DatasetError, before anything runs or is
allocated."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from crafted import (
    deep_key_pickle,
    fake_subarray_pickle,
    huge_ndarray_pickle,
    huge_reconstruct_pickle,
    memo_pickle,
    sparse_pickle,
    write_good_pickle,
)

from handover_env.data import DatasetError, load_public_dataset
from handover_env.data.__main__ import main
from handover_env.data.limits import MAX_MEMO_ENTRIES, MAX_PICKLE_BYTES, MAX_PICKLE_DEPTH
from handover_env.data.public import LoadReport, load_public_file

REPO = Path(__file__).resolve().parents[1]


def test_deep_nesting_is_refused_in_a_child_process_that_survives(tmp_path: Path) -> None:
    """Item 4: a 200 KB pickle with a dict key nested 200,000 deep used to segfault the loader."""
    folder = tmp_path / "pub"
    folder.mkdir()
    deep_key_pickle(folder / "motion_normal_1.pkl")
    assert (folder / "motion_normal_1.pkl").stat().st_size > 200_000
    write_good_pickle(folder / "motion_normal_0.pkl")
    write_good_pickle(folder / "motion_normal_2.pkl", seed=2)
    code = (
        "import sys; from handover_env.data.__main__ import main; "
        f"sys.exit(main(['convert', '--skip-bad', {str(folder)!r}, {str(tmp_path / 'out.npz')!r}]))"
    )
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                            timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)}, check=False)
    assert result.returncode == 0, (result.returncode, result.stderr[-2000:])  # not -11 (SIGSEGV)
    assert "loaded 2 file(s), skipped 1" in result.stdout
    assert (
        f"skipped motion_normal_1.pkl: refused to load: objects nested {MAX_PICKLE_DEPTH + 1} deep"
        in result.stdout
    )


@pytest.mark.parametrize(
    "builder, message",
    [
        (huge_ndarray_pickle, r"REDUCE calls numpy\.ndarray"),
        (
            huge_reconstruct_pickle,
            r"_reconstruct called other than as _reconstruct\(ndarray, \(0,\), b'b'\)",
        ),
        (memo_pickle, rf"memo index 2147483647 \(at most {MAX_MEMO_ENTRIES - 1}\)"),
        (sparse_pickle, rf"3,200,000,000 bytes, more than the {MAX_PICKLE_BYTES:,}"),
    ],
    ids=["ndarray-3GiB", "reconstruct-2GiB", "memo-index", "sparse-3.2GB"],
)
def test_declared_sizes_are_bounded_before_allocation(
    tmp_path: Path, builder, message: str
) -> None:
    """Item 5: declared arrays, memo indices and file sizes are checked before anything is
    allocated."""
    path = builder(tmp_path / "motion_normal_3.pkl")
    assert path.stat().st_blocks * 512 < 1_000_000  # the file itself is tiny on disk
    with pytest.raises(DatasetError, match=rf"motion_normal_3\.pkl: .*{message}"):
        load_public_file(path)


def test_array_state_must_match_the_bytes_in_the_file(tmp_path: Path) -> None:
    """Item 5: an array whose state declares more data than the file holds is refused by the
    scan."""
    import pickle

    from crafted import good_record

    raw = pickle.dumps(good_record(t=10), protocol=4)
    # pose_receiver declares (10, 34, 3); make it declare (100, 34, 3) without adding bytes
    patched = raw.replace(b"K\nK\"K\x03\x87", b"KdK\"K\x03\x87", 1)
    assert patched != raw
    path = tmp_path / "motion_normal_4.pkl"
    path.write_bytes(patched)
    with pytest.raises(DatasetError, match=r"declares 81,600 bytes but the file holds 8,160"):
        load_public_file(path)


def test_fake_subarray_dtype_is_a_named_error_that_skip_bad_skips(tmp_path: Path, capsys) -> None:
    """Item 6: a dtype with a fake sub-array gave a bare MemoryError/ValueError and aborted
    convert."""
    folder = tmp_path / "pub"
    folder.mkdir()
    fake_subarray_pickle(folder / "motion_variation_0.pkl")
    write_good_pickle(folder / "motion_normal_0.pkl")
    with pytest.raises(
        DatasetError,
        match=r"motion_variation_0\.pkl: refused to load: a dtype state with .*sub-array",
    ):
        load_public_file(folder / "motion_variation_0.pkl")
    report = LoadReport()
    ds = load_public_dataset(
        folder, skip_bad=True, progress=False, report=report, on_skip=lambda *a: None
    )
    assert len(ds) == 1 and [name for name, _ in report.skipped] == ["motion_variation_0.pkl"]
    capsys.readouterr()
    assert main(["convert", "--skip-bad", str(folder), str(tmp_path / "out.npz")]) == 0
    assert "skipped motion_variation_0.pkl: refused to load" in capsys.readouterr().out


def test_every_error_names_the_file(tmp_path: Path) -> None:
    """Item 6: whatever goes wrong inside one file's load, the error is a DatasetError naming it."""
    from unittest import mock

    path = write_good_pickle(tmp_path / "motion_normal_0.pkl")
    with (
        mock.patch(
            "handover_env.data.public.canonical_quaternions", side_effect=MemoryError("boom")
        ),
        pytest.raises(
            DatasetError, match=r"motion_normal_0\.pkl: cannot load \(MemoryError: boom\)"
        ),
    ):
        load_public_file(path)
