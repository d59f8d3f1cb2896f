"""Crafted and malicious dataset files, generated in a test's tmp_path (nothing of this is
committed).

Each builder writes one file and returns its path. The pickles are assembled opcode by opcode so
that they say exactly what the attack needs and nothing else.
"""

from __future__ import annotations

import io
import pickle
import struct
import zipfile
from pathlib import Path

import numpy as np

PROTO4 = b"\x80\x04"
STOP = b"."


def _u(text: str) -> bytes:
    """SHORT_BINUNICODE."""
    raw = text.encode()
    return b"\x8c" + bytes([len(raw)]) + raw


def _int(value: int) -> bytes:
    """BININT (signed 32 bit)."""
    return b"J" + struct.pack("<i", value)


def _global(module: str, name: str) -> bytes:
    return _u(module) + _u(name) + b"\x93"  # STACK_GLOBAL


def good_record(t: int = 40, seed: int = 0) -> dict[str, np.ndarray]:
    """A valid public-dataset recording."""
    rng = np.random.default_rng(seed)
    quat = rng.standard_normal((t, 4))
    return {
        "pose_receiver": rng.standard_normal((t, 34, 3)),
        "pose_giver": rng.standard_normal((t, 34, 3)),
        "pose_object": rng.standard_normal((t, 3)),
        "quat_object": quat / np.linalg.norm(quat, axis=1, keepdims=True),
    }


def write_good_pickle(path: Path, t: int = 40, seed: int = 0) -> Path:
    path.write_bytes(pickle.dumps(good_record(t, seed), protocol=4))
    return path


def deep_key_pickle(path: Path, depth: int = 200_000) -> Path:
    """A dict whose key is a tuple nested ``depth`` deep: hashing it overflows CPython's C stack."""
    key = b")" + b"\x85" * depth  # EMPTY_TUPLE, then TUPLE1 over and over
    path.write_bytes(PROTO4 + b"}" + key + b"N" + b"s" + STOP)  # EMPTY_DICT key NONE SETITEM
    return path


def huge_ndarray_pickle(path: Path, rows: int = 2**27) -> Path:
    """``pose_object`` built by calling ``numpy.ndarray((rows, 3), float64)``: 3 GiB from 200
    bytes."""
    dtype = _global("numpy", "dtype") + _u("f8") + b"\x89\x88\x87R"  # dtype('f8', False, True)
    shape = _int(rows) + b"K\x03" + b"\x86"  # (rows, 3)
    array = _global("numpy", "ndarray") + shape + dtype + b"\x86R"  # ndarray(shape, dtype)
    path.write_bytes(PROTO4 + b"}" + _u("pose_object") + array + b"s" + STOP)
    return path


def huge_reconstruct_pickle(path: Path) -> Path:
    """``_reconstruct(ndarray, (2**31,), b'b')``: numpy allocates the declared shape (2 GiB)."""
    call = (_global("numpy._core.multiarray", "_reconstruct") + _global("numpy", "ndarray")
            + _int(2**31 - 1) + b"\x85" + b"C\x01b" + b"\x87R")
    path.write_bytes(PROTO4 + b"}" + _u("pose_object") + call + b"s" + STOP)
    return path


def memo_pickle(path: Path) -> Path:
    """Nine bytes: NONE stored at memo index 2**31 - 1 (the C unpickler sizes its table to it)."""
    path.write_bytes(PROTO4 + b"N" + b"r" + struct.pack("<I", 2**31 - 1) + STOP)
    return path


def sparse_pickle(path: Path, size: int = 3_200_000_000) -> Path:
    """A 3.2 GB file that takes no disk space (a hole): reading it whole asks for 3.2 GB."""
    with open(path, "wb") as f:
        f.truncate(size)
    return path


def fake_subarray_pickle(path: Path, elements: int = 2**30) -> Path:
    """A valid recording whose first dtype state claims an ``elements``-long float64 sub-array."""
    good = pickle.dumps(good_record(), protocol=4)
    base = _global("numpy", "dtype") + _u("f8") + b"\x89\x88\x87R"  # dtype('f8', False, True)
    sub = (_u("<") + base + _int(elements) + b"\x85" + b"\x86"  # (dtype, (elements,))
           + b"NN" + _int(8) + _int(8) + b"K\x00" + b"t")
    return _patch_first_dtype_state(path, good, sub)


def _patch_first_dtype_state(path: Path, good: bytes, sub_state: bytes) -> Path:
    """Replace the body of the first dtype state tuple (after ``MARK 3``) by ``sub_state``."""
    import pickletools

    ops = list(pickletools.genops(good))
    for i, (op, arg, pos) in enumerate(ops):
        if op.name == "SHORT_BINUNICODE" and arg in ("<", "|") and ops[i - 1][0].name == "BININT1" \
                and ops[i - 1][1] == 3 and ops[i - 2][0].name == "MARK":
            start = pos
            # the state tuple ends at the first TUPLE opcode after it
            end = next(p for o, _, p in ops[i:] if o.name == "TUPLE") + 1
            path.write_bytes(good[:start] + sub_state + good[end:])
            return path
    raise AssertionError("no dtype state found")


# ---------------------------------------------------------------------- npz files
def npz_members(dataset) -> dict[str, np.ndarray]:
    """The members :meth:`HandoverDataset.save` writes, as arrays."""
    return {
        "format_version": np.array(1, dtype=np.int64),
        "rate_hz": np.array(dataset.rate_hz, dtype=np.float64),
        "name": np.array(dataset.name),
        "lengths": dataset.lengths,
        "is_ood": dataset.ood_mask,
        "source_id": np.array([ep.source_id for ep in dataset]),
        "receiver_xy": np.concatenate([ep.receiver_xy for ep in dataset]),
        "receiver_hand_xyz": np.concatenate([ep.receiver_hand_xyz for ep in dataset]),
        "giver_xyz": np.concatenate([ep.giver_xyz for ep in dataset]),
        "object_quat": np.concatenate([ep.object_quat for ep in dataset]),
    }


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(array), allow_pickle=False)
    return buf.getvalue()


def lying_header_npy(shape: tuple[int, ...], dtype: str = "<f8", data: bytes = b"\0" * 16) -> bytes:
    """A ``.npy`` whose header declares ``shape`` while only ``data`` follows."""
    header = {"descr": dtype, "fortran_order": False, "shape": shape}
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, header)
    return buf.getvalue() + data


def write_npz(path: Path, members: dict[str, np.ndarray | bytes]) -> Path:
    """An ``.npz`` of ``members`` (arrays, or raw ``.npy`` bytes for crafted members)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for key, value in members.items():
            zf.writestr(f"{key}.npy", value if isinstance(value, bytes) else _npy_bytes(value))
    return path


def many_members_npz(path: Path, declared: int = 60_000) -> Path:
    """A small zip whose end-of-directory record claims ``declared`` members."""
    write_npz(path, {"x": np.zeros(1)})
    raw = bytearray(path.read_bytes())
    eocd = raw.rfind(b"PK\x05\x06")
    struct.pack_into("<HH", raw, eocd + 8, declared, declared)
    path.write_bytes(bytes(raw))
    return path


def make_folder(folder: Path, builder, name: str = "motion_normal_0.pkl") -> Path:
    """``folder`` holding one crafted file ``name`` made by ``builder(path)``."""
    folder.mkdir(parents=True, exist_ok=True)
    builder(folder / name)
    return folder


