"""Issue 16 acceptance: under a 2 GB address-space limit, ``convert`` and ``info`` on every crafted
file end with a clear error naming the file: no crash, no out-of-memory kill, no traceback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import crafted
import numpy as np
from baselines_toy import toy_dataset

REPO = Path(__file__).resolve().parents[2]
LIMIT = 2 << 30  # bytes of address space

PICKLES = {
    "deep_key": crafted.deep_key_pickle,
    "huge_ndarray": crafted.huge_ndarray_pickle,
    "huge_reconstruct": crafted.huge_reconstruct_pickle,
    "memo": crafted.memo_pickle,
    "sparse": crafted.sparse_pickle,
    "fake_subarray": crafted.fake_subarray_pickle,
}

# Runs in the limited child: every command through the CLI's main(), stderr captured per command.
CHILD = r"""
import contextlib, io, json, resource, sys
resource.setrlimit(resource.RLIMIT_AS, ({limit}, {limit}))
from handover_eval.cli.data import main
results = []
for argv in json.loads(sys.argv[1]):
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = main(argv)
    results.append({{"argv": argv, "rc": rc, "err": err.getvalue(), "out": out.getvalue()}})
# VmHWM: this process's own peak resident memory (ru_maxrss would include the parent's, kept
# across exec)
hwm = [line for line in open("/proc/self/status") if line.startswith("VmHWM:")][0].split()[1]
results.append({{"peak_rss_mb": int(hwm) / 1024}})
print(json.dumps(results))
"""


def test_crafted_files_end_with_named_errors_under_2gb(tmp_path: Path) -> None:
    commands, expected = [], []
    for name, build in PICKLES.items():
        folder = crafted.make_folder(tmp_path / name, build)
        bad = folder / "motion_normal_0.pkl"
        commands += [["convert", str(folder), str(tmp_path / f"{name}.npz")], ["info", str(folder)]]
        expected += [bad, bad]
    members = crafted.npz_members(toy_dataset(n=3, length=40, seed=0))
    npz_files = {
        "header_lie": crafted.write_npz(
            tmp_path / "header_lie.npz",
            {**members, "receiver_xy": crafted.lying_header_npy((10**9, 2))},
        ),
        "directory": crafted.many_members_npz(tmp_path / "directory.npz"),
        "far": crafted.write_npz(
            tmp_path / "far.npz",
            {**members, "giver_xyz": np.full_like(members["giver_xyz"], 1e308)},
        ),
    }
    for path in npz_files.values():
        commands.append(["info", str(path)])
        expected.append(path)
    good = crafted.make_folder(
        tmp_path / "good", crafted.write_good_pickle
    )  # the limit itself is fine
    commands += [
        ["convert", str(good), str(tmp_path / "good.npz")],
        ["info", str(tmp_path / "good.npz")],
    ]

    child = subprocess.run(
        [sys.executable, "-c", CHILD.format(limit=LIMIT), json.dumps(commands)],
        cwd=REPO, capture_output=True, text=True, timeout=300, check=False,
        env={**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"},
    )
    assert child.returncode == 0, f"child died with {child.returncode}: {child.stderr[-3000:]}"
    *results, usage = json.loads(child.stdout.strip().splitlines()[-1])
    for result, path in zip(results, expected):
        lines = [line for line in result["err"].replace("\r", "\n").splitlines() if line.strip()]
        errors = [line for line in lines if not line.startswith("loading ")]  # not the progress bar
        assert result["rc"] == 2, result
        assert len(errors) == 1 and errors[0].startswith(f"error: {path}: "), result
        assert "Traceback" not in result["err"] and "MemoryError" not in errors[0], result
    assert [r["rc"] for r in results[len(expected):]] == [0, 0]
    assert usage["peak_rss_mb"] < 1024, usage  # nothing came near the limit
