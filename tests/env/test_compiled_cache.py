"""A kernel of :func:`handover_env.compiled.kernel` in a read-only package still starts warm.

numba looks for a cache folder in order (``_CacheImpl._locator_classes`` of
``numba/core/caching.py``): ``NUMBA_CACHE_DIR`` if set, else ``__pycache__`` beside the source
if it can write there, else the user-wide cache folder (``$XDG_CACHE_HOME/numba`` or
``~/.cache/numba``). Here the package's folder is read-only (its mode bits, and ``__pycache__`` a
plain file, which stops even root from caching in the tree) and ``NUMBA_CACHE_DIR`` is unset: the
first process compiles and writes its machine code to the user-wide folder, the second loads it
from there.
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

PROBE = '''
from handover_env.compiled import kernel


@kernel
def scaled_sum(x, a):
    s = 0.0
    for v in x:
        s += a * v
    return s
'''

RUN = '''
import json
import numpy as np
import ro_kernel_probe as m

value = m.scaled_sum(np.arange(4.0), 0.5)
stats = m.scaled_sum.stats
print(json.dumps({"value": value, "hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values()), "path": stats.cache_path}))
'''


def _run(pkg: Path, cache_home: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(cache_home)
    env["PYTHONPATH"] = os.pathsep.join([str(pkg), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True,
                         timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_read_only_package_loads_kernels_from_the_user_cache(tmp_path: Path) -> None:
    pkg, cache_home = tmp_path / "pkg", tmp_path / "cache"
    pkg.mkdir()
    (pkg / "ro_kernel_probe.py").write_text(PROBE)
    (pkg / "__pycache__").write_text("")  # not a folder: numba cannot cache in the tree
    read_only = stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH
    for path in pkg.iterdir():
        path.chmod(read_only)
    pkg.chmod(read_only | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    try:
        first = _run(pkg, cache_home)
        second = _run(pkg, cache_home)
    finally:
        pkg.chmod(stat.S_IRWXU)
    assert first["value"] == second["value"] == 3.0
    assert (first["misses"], first["hits"]) == (1, 0)  # compiled, then saved
    assert (second["misses"], second["hits"]) == (0, 1)  # loaded: no compilation
    assert Path(first["path"]).is_relative_to(cache_home / "numba")
    assert len(list(Path(first["path"]).glob("ro_kernel_probe.scaled_sum-*.nbi"))) == 1
    assert sorted(p.name for p in pkg.iterdir()) == ["__pycache__", "ro_kernel_probe.py"]


def test_no_writable_cache_folder_compiles_without_a_cache(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "ro_kernel_probe.py").write_text(PROBE)
    (pkg / "__pycache__").write_text("")
    blocked = tmp_path / "not_a_folder"
    blocked.write_text("")  # the user cache folder would be inside a file: no folder is writable
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(XDG_CACHE_HOME=str(blocked / "cache"), PYTHONPATH=os.pathsep.join(
        [str(pkg), env.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True,
                         timeout=300, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["value"] == 3.0 and result["path"] is None
    assert "compiled without a cache" in out.stderr
