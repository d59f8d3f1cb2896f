"""Issue 16 items 4-6, issue 20 item 9 (dtypes, protocols): crafted pickles end with a named
DatasetError, before anything runs or is allocated."""

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
from handover_env.data.limits import MAX_MEMO_ENTRIES, MAX_PICKLE_BYTES, MAX_PICKLE_DEPTH
from handover_env.data.public import LoadReport, load_public_file
from handover_eval.cli.data import main

REPO = Path(__file__).resolve().parents[2]


def test_deep_nesting_is_refused_in_a_child_process_that_survives(tmp_path: Path) -> None:
    """Item 4: a 200 KB pickle with a dict key nested 200,000 deep used to segfault the loader."""
    folder = tmp_path / "pub"
    folder.mkdir()
    deep_key_pickle(folder / "motion_normal_1.pkl")
    assert (folder / "motion_normal_1.pkl").stat().st_size > 200_000
    write_good_pickle(folder / "motion_normal_0.pkl")
    write_good_pickle(folder / "motion_normal_2.pkl", seed=2)
    code = (
        "import sys; from handover_eval.cli.data import main; "
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


# ---------------------------------------------------------------------- issue 20 item 9: dtypes
def _big_endian_record() -> dict:
    from crafted import good_record

    record = good_record(t=12)
    record["pose_object"] = record["pose_object"].astype(">f8")
    return record


def test_a_big_endian_array_keeps_its_values(tmp_path: Path) -> None:
    """numpy's own big-endian pickle (dtype(code, False, True) + state '>') is read correctly."""
    import pickle

    import numpy as np

    record = _big_endian_record()
    path = tmp_path / "motion_normal_5.pkl"
    path.write_bytes(pickle.dumps(record, protocol=4))
    episode = load_public_file(path)
    np.testing.assert_array_equal(episode.giver_xyz, record["pose_object"].astype("<f8"))


def test_a_copy_false_dtype_is_refused_not_misread(tmp_path: Path) -> None:
    """``dtype('f8', False, False)`` returns numpy's shared dtype, which ignores the '>' state:
    the array's bytes were silently read as little-endian numbers."""
    import pickle

    import numpy as np

    record = _big_endian_record()
    good = pickle.dumps(record, protocol=4)
    crafted = good.replace(b"\x89\x88\x87", b"\x89\x89\x87")  # (False, True) -> (False, False)
    assert crafted != good and len(crafted) == len(good)
    misread = pickle.loads(crafted)["pose_object"]  # what a plain unpickler makes of it
    assert not np.array_equal(misread, record["pose_object"])
    path = tmp_path / "motion_normal_6.pkl"
    path.write_bytes(crafted)
    with pytest.raises(
        DatasetError,
        match=r"motion_normal_6\.pkl: refused to load: dtype\('f8', align=False, copy=False\): "
        r"numpy pickles dtype\(code, False, True\)",
    ):
        load_public_file(path)


# ---------------------------------------------------------------------- issue 20 item 9: protocols
@pytest.mark.parametrize("protocol", [3, 4, 5])
def test_numpy_pickles_of_protocols_3_to_5_load(tmp_path: Path, protocol: int) -> None:
    """Protocol 5 pickles arrays as ``_frombuffer(bytearray, dtype, shape, order)``; it was
    refused although protocols 3-5 were documented."""
    import pickle

    import numpy as np
    from crafted import good_record

    from handover_env.data.pickle_scan import scan_pickle
    from handover_env.data.public import safe_load_pickle

    plain = tmp_path / "plain.pkl"
    plain.write_bytes(pickle.dumps(np.arange(3), protocol=protocol))
    scan_pickle(plain.read_bytes(), "plain.pkl")
    np.testing.assert_array_equal(safe_load_pickle(plain), np.arange(3))
    record = good_record(t=12)
    record["pose_giver"] = np.asfortranarray(record["pose_giver"])  # order 'F' at protocol 5
    record["pose_object"] = record["pose_object"].astype(">f8")
    path = tmp_path / "motion_normal_7.pkl"
    path.write_bytes(pickle.dumps(record, protocol=protocol))
    loaded = safe_load_pickle(path)
    for key, value in record.items():
        np.testing.assert_array_equal(loaded[key], value)
    episode = load_public_file(path)
    np.testing.assert_array_equal(episode.giver_xyz, record["pose_object"])


@pytest.mark.parametrize(
    "make, message",
    [
        ("out-of-band", r"an out-of-band buffer \(NEXT_BUFFER\)"),
        ("protocol-2", r"pickle protocol 2 \(this loader reads 3 to 5\)"),
        ("short-buffer", r"declares 288 bytes but the file holds 280"),
        ("bad-order", r"_frombuffer called other than as _frombuffer\(bytes, dtype, shape, 'C'"),
    ],
)
def test_protocol_5_buffers_are_checked(tmp_path: Path, make: str, message: str) -> None:
    import pickle

    from crafted import good_record

    record = good_record(t=12)
    if make == "out-of-band":
        raw = pickle.dumps(record, protocol=5, buffer_callback=lambda buf: False)
    elif make == "protocol-2":
        raw = pickle.dumps(record, protocol=2)
    else:
        raw = pickle.dumps(record, protocol=5)
        if make == "short-buffer":  # pose_object (12, 3): the buffer loses its last 8 bytes
            start = raw.index(b"\x96" + (12 * 3 * 8).to_bytes(8, "little"))  # BYTEARRAY8
            head, data = raw[:start], raw[start + 9:start + 9 + 280]
            raw = head + b"\x96" + (280).to_bytes(8, "little") + data + raw[start + 9 + 288:]
        else:
            raw = raw.replace(b"\x8c\x01C", b"\x8c\x01K", 1)
    path = tmp_path / "motion_normal_8.pkl"
    path.write_bytes(raw)
    with pytest.raises(DatasetError, match=rf"motion_normal_8\.pkl: refused to load: .*{message}"):
        load_public_file(path)
