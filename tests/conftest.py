"""The test families' shared root.

The tests live in one folder per family (``security/``, ``env/``, ``person/``, ``data/``,
``agents/``, ``baselines/``, ``eval/``, ``project/``). The helpers that several families use stay
here and are imported by bare name: ``crafted`` (hostile files built in a temporary folder),
``baselines_toy`` (a tiny synthetic dataset for the learned baselines), ``quadratic_users``
(closed-form preference users for CoSpar) and ``planted`` (a checkpoint commit planted out of its
folder, and the check that nothing moved). This folder is put on ``sys.path`` once, here.

The quick evaluation runs that several test files compare against are fixtures here:
``table1 --quick`` (every method), ``sample-efficiency --quick``, a 6-agent ``closed-loop --quick``
and the every-agent ``closed-loop --quick`` on the ideal sensing profile. Each is run once per test
session, by whichever pytest-xdist worker asks first: into a folder shared by the session's
workers, under an exclusive ``flock``, marked finished by a ``DONE`` file holding its argv (what
it printed is in ``stdout.txt``). A worker finding the marker reuses the run; one finding none (a
run that failed) runs it again. The runs are read only: a test that runs more on top copies the
checkpoints it needs.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import json
import os
import shutil
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
if str(TESTS) not in sys.path:
    sys.path.insert(0, str(TESTS))

#: numpy's dispatched AVX-512 paths (numpy 2.x on x86-64), turned off for the test session.
NUMPY_AVX512 = ("AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX AVX512_CNL "
                "AVX512_ICL AVX512_SPR")


def _pin_numeric_paths() -> None:
    """Give numpy and its OpenBLAS the code paths the compiled kernels' references are.

    The kernels sum small products in a stated order (:mod:`handover_env.kernel_math`): numpy's
    ``matmul`` and ``dot`` as OpenBLAS's Haswell kernels compute them, its ``exp`` as its AVX2
    loop does. The kernels' own bits do not depend on the CPU; numpy's do: on a CPU with AVX-512,
    OpenBLAS picks its SkylakeX kernels and numpy its AVX-512 loops, whose sums are in another
    order, and the bit-for-bit tests of the kernels against numpy (tests/env/test_compiled_*.py,
    tests/agents/test_flow_kernels.py) then differ in the last bits. So on any x86-64 CPU with AVX2
    and FMA, the test session asks for the Haswell kernels (``OPENBLAS_CORETYPE``) and turns
    numpy's AVX-512 dispatch off (``NPY_DISABLE_CPU_FEATURES``; names this numpy does not
    dispatch are ignored with an ImportWarning). Both are read when the libraries load, so this
    runs before anything imports numpy; a value the user set is kept; pytest-xdist's workers
    inherit it."""
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return
    if "avx2" not in flags or "fma" not in flags:
        return
    if "numpy" in sys.modules and "OPENBLAS_CORETYPE" not in os.environ:
        warnings.warn("numpy was imported before tests/conftest.py could pin its code paths: "
                      "the kernels' bit-for-bit tests may differ from numpy in the last bits "
                      "(run with OPENBLAS_CORETYPE=Haswell and NPY_DISABLE_CPU_FEATURES set)",
                      stacklevel=1)
    os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")
    os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", NUMPY_AVX512)


_pin_numeric_paths()

#: The agents of the shared closed-loop run: the baseline, two fold models and the three
#: model-free agents (``giver-replay`` on the replays only).
CLOSED_LOOP_AGENTS = ["reactive", "ours", "bc-mlp", "lagging", "static", "giver-replay"]


def _session_root(factory: pytest.TempPathFactory) -> Path:
    """A folder every worker of this session sees: the parent of a worker's own base temp."""
    base = factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def shared_run(factory: pytest.TempPathFactory, name: str, argv: list[str]) -> Path:
    """``evaluate.main(argv)`` into ``<folder>/out`` (closed-loop: ``--checkpoints
    <folder>/checkpoints``), run once per session across workers; returns ``<folder>``."""
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
    import evaluate

    folder = _session_root(factory) / "shared-runs" / name
    folder.parent.mkdir(parents=True, exist_ok=True)
    done = folder / "DONE"
    with open(folder.parent / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if done.is_file():
            assert json.loads(done.read_text()) == argv, f"shared run {name}: another argv"
            return folder
        shutil.rmtree(folder, ignore_errors=True)  # a run that failed before its marker
        folder.mkdir()
        full = argv + ["--out", str(folder / "out")]
        if argv[0] == "closed-loop":  # the open-loop commands keep theirs in <out>/checkpoints
            full += ["--checkpoints", str(folder / "checkpoints")]
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            status = evaluate.main(full)
        (folder / "stdout.txt").write_text(printed.getvalue())
        assert status == 0, f"shared run {name} failed: {printed.getvalue()[-2000:]}"
        done.write_text(json.dumps(argv))
    return folder


def _shared(name: str, argv: list[str]) -> Callable[[pytest.TempPathFactory], Path]:
    @pytest.fixture(scope="session", name=name)
    def fixture(tmp_path_factory: pytest.TempPathFactory) -> Path:
        return shared_run(tmp_path_factory, name, argv)

    fixture.__doc__ = f"``evaluate.py {' '.join(argv)}``, once per session (the folder)."
    return fixture


#: ``table1 --quick`` with every open-loop method, folds in 2 worker processes (the default on 2
#: or more cores, given explicitly so the serial-loop comparison compares 1 with 2).
table1_quick = _shared("table1_quick", ["table1", "--quick", "--no-progress", "--workers", "2"])

#: ``sample-efficiency --quick`` of the SPGP and BC-MLP at ratios 0.5 and 1.
sample_efficiency_quick = _shared(
    "sample_efficiency_quick",
    ["sample-efficiency", "--quick", "--no-progress", "--methods", "ours", "bc_mlp",
     "--ratios", "0.5", "1.0"],
)

#: ``closed-loop --quick`` of CLOSED_LOOP_AGENTS in 2 worker processes (default sensing).
closed_loop_quick = _shared(
    "closed_loop_quick",
    ["closed-loop", "--quick", "--no-progress", "--workers", "2", "--agents",
     *CLOSED_LOOP_AGENTS],
)

#: ``closed-loop --quick`` with every agent (the RL ones trained on the spot), on the ideal
#: sensing profile: the exact world test_closed_loop.py's checks were written for (issue 24).
closed_loop_every_agent = _shared(
    "closed_loop_every_agent", ["closed-loop", "--quick", "--no-progress", "--sensing", "ideal"]
)
