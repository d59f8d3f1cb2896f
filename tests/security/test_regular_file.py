"""The one bounded read of outside files: regular, inside their folder, checked on the open file."""

from __future__ import annotations

import os
import sys

import pytest
import torch
from safetensors.torch import save_file

from baselines.checkpoint_io import (
    MAX_JSON_BYTES,
    CheckpointError,
    check_loadable,
    load_tensors,
    read_json,
)
from handover_env.regular_file import UnsafeFileError, read_regular_file

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="/proc/self/fd names an open file on Linux only")


def _folders(tmp_path, name: str, secret: str, text: str):
    """``tmp_path/outside`` holding the file ``secret`` and an empty folder ``tmp_path/name``."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / secret).write_text(text)
    root = tmp_path / name
    root.mkdir()
    return outside, root


def test_reads_a_regular_file_and_its_inside_link(tmp_path):
    (tmp_path / "a.bin").write_bytes(b"abc")
    (tmp_path / "link.bin").symlink_to("a.bin")
    assert read_regular_file(tmp_path / "a.bin", 3, tmp_path) == b"abc"
    assert read_regular_file(tmp_path / "link.bin", 3, tmp_path) == b"abc"


def test_refuses_what_is_not_a_bounded_regular_file_inside_its_folder(tmp_path):
    outside, root = _folders(tmp_path, "root", "secret.json", "{}")
    (root / "out.json").symlink_to(outside / "secret.json")
    (root / "gone.json").symlink_to(root / "nothing")
    (root / "loop.json").symlink_to(root / "loop.json")
    (root / "dir.json").mkdir()
    os.mkfifo(root / "fifo.json")
    with open(root / "big.json", "wb") as f:  # sparse: its size is reported, never read
        f.truncate(11)
    cases = {"out.json": "outside the folder", "gone.json": "dangling symbolic link",
             "loop.json": "symbolic link loop", "dir.json": "a folder, not a file",
             "fifo.json": "not a regular file", "big.json": "11 bytes, more than the 10 a file"}
    for name, match in cases.items():
        with pytest.raises(UnsafeFileError, match=match):
            read_regular_file(root / name, 10, root)


@linux_only
def test_a_folder_on_the_path_swapped_for_a_link_out_is_refused(tmp_path):
    # A name check sees only the last component; a linked folder on the way is caught on the
    # open file itself.
    outside, root = _folders(tmp_path, "ckpt", "state.json", '{"x": 1}')
    (root / "training_state").symlink_to(outside)
    with pytest.raises(UnsafeFileError, match=r"opened .*outside the folder"):
        read_regular_file(root / "training_state" / "state.json", 100, root)
    with pytest.raises(CheckpointError, match="outside the checkpoint folder"):
        read_json(root / "training_state" / "state.json", "training state", root=root)


def test_a_checkpoint_file_swapped_for_a_link_after_the_folder_check_is_not_read(tmp_path):
    folder = tmp_path / "ckpt"
    folder.mkdir()
    outside = tmp_path / "elsewhere.safetensors"
    save_file({"w": torch.ones(2)}, str(outside))
    save_file({"w": torch.zeros(2)}, str(folder / "model.safetensors"))
    check_loadable(folder, ["model.safetensors"], "test")  # passes: the file is inside
    (folder / "model.safetensors").unlink()  # ... then the file becomes a link out
    (folder / "model.safetensors").symlink_to(outside)
    with pytest.raises(CheckpointError, match="outside the checkpoint folder"):
        load_tensors(folder / "model.safetensors", {"w": ((2,), torch.float32)})


def test_checkpoint_reads_give_their_own_errors(tmp_path):
    save_file({"w": torch.arange(3.0)}, str(tmp_path / "m.safetensors"))
    assert torch.equal(load_tensors(tmp_path / "m.safetensors")["w"], torch.arange(3.0))
    with pytest.raises(CheckpointError, match="m2.safetensors: missing"):
        load_tensors(tmp_path / "m2.safetensors")
    with open(tmp_path / "big.json", "wb") as f:
        f.truncate(MAX_JSON_BYTES + 1)
    with pytest.raises(CheckpointError, match=f"{MAX_JSON_BYTES + 1:,} bytes, more than"):
        read_json(tmp_path / "big.json")
    (tmp_path / "bad.json").write_bytes(b"\xff{")
    with pytest.raises(CheckpointError, match="not valid JSON"):
        read_json(tmp_path / "bad.json")
    (tmp_path / "ok.json").write_text("[1]")
    assert read_json(tmp_path / "ok.json") == [1]
