"""Per-frame cost of the SPGP planner against IAAL (exact GP), side by side, on one core.

One streaming frame = ``stream_update(new receiver xy)`` + ``stream_predict()`` (the chunk the
closed loop ensembles), for a planner fitted on every episode of the 875-episode development
copy of the public dataset (``../shared/data/dynamic_handover_dataset/whole_motions``; the
synthetic default dataset when it is absent). Recorded receiver tracks are replayed frame by
frame; the planners take turns track by track so both see the same machine load.

Printed: median and p99 wall time and CPU time (``thread_time``: not inflated when the shared
machine deschedules us) per frame, for ours at inducing ratio 0.4 and IAAL, their ratio, and
the prediction of that ratio from the stored per-query entries (sum over demos of
(M_k + 2) M_k for FITC against (N_k + 2) N_k for the exact GP: the variance mat-vec dominates);
then the cost at inducing ratios 0.1 ... 1.0.

``--against REV`` also times the planner code (ours and IAAL) of git revision REV (its ``agents/``
extracted with ``git archive`` into a temporary folder and imported as ``agents_REV``, the current
``handover_env`` underneath) interleaved with today's, on the same data, and reports both
revisions' IAAL / ours ratios and the largest difference of their chunks. ``--busy`` keeps a
second process spinning on the other core while it measures.

Usage: ``python bench/planner_latency.py [--quick] [--data PATH] [--precision float32|float64]
[--against REV] [--busy]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: set before numpy loads its BLAS

import argparse  # noqa: E402
import importlib  # noqa: E402
import re  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tarfile  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.nonparametric import NonparametricAgent, NonparametricConfig  # noqa: E402
from baselines.iaal import IAALAgent  # noqa: E402
from handover_env.person.demos import load_any  # noqa: E402

DEV_COPY = (
    Path(__file__).resolve().parents[1]
    / ".."
    / "shared"
    / "data"
    / "dynamic_handover_dataset"
    / "whole_motions"
)
RATIOS = (0.1, 0.2, 0.4, 0.6, 0.8, 1.0)


def _pin_one_core() -> str:
    try:
        cores = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cores[0]})
        return (
            f"pinned to core {cores[0]} of {len(cores)} available ({os.cpu_count()} in the machine)"
        )
    except (AttributeError, OSError):
        return f"not pinned (no sched_setaffinity); {os.cpu_count()} cores"


def _frame_costs(
    agents: list[NonparametricAgent], tracks: list[np.ndarray]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(wall, cpu) seconds per frame for each agent, replaying ``tracks``.

    The agents take turns track by track (same machine load for both, in blocks long enough
    that each runs with its own data in cache, as it would in a control loop).
    """
    wall = [[] for _ in agents]
    cpu = [[] for _ in agents]
    for track in tracks:
        for i, a in enumerate(agents):
            a.stream_reset()
            a.stream_update(track[0])  # warm-up frame, not timed
            a.stream_reset()
            for xy in track:
                w0, c0 = time.perf_counter(), time.thread_time()
                a.stream_update(xy)
                a.stream_predict()
                cpu[i].append(time.thread_time() - c0)
                wall[i].append(time.perf_counter() - w0)
    return [(np.asarray(w), np.asarray(c)) for w, c in zip(wall, cpu)]


def _planner_of_revision(rev: str, folder: Path):
    """``NonparametricAgent`` of git revision ``rev``: its agents/ as package ``agents_<rev>``."""
    root = Path(__file__).resolve().parents[1]
    tar = folder / "agents.tar"
    with open(tar, "wb") as f:
        subprocess.run(["git", "-C", str(root), "archive", rev, "agents"], stdout=f, check=True)
    with tarfile.open(tar) as t:
        t.extractall(folder, filter="data")
    name = "agents_" + re.sub(r"\W", "_", rev)
    (folder / "agents").rename(folder / name)
    for py in (folder / name).glob("*.py"):
        src = py.read_text()
        py.write_text(re.sub(r"\b(from|import) agents(\.| )", rf"\1 {name}\2", src))
    sys.path.insert(0, str(folder))
    return importlib.import_module(f"{name}.nonparametric")


def _fmt(x: np.ndarray) -> str:
    return f"median {np.median(x) * 1e3:6.3f} ms  p99 {np.percentile(x, 99) * 1e3:6.3f} ms"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="fewer replayed frames")
    parser.add_argument(
        "--data",
        default=None,
        help="dataset folder or .npz (default: the dev copy, else synthetic)",
    )
    parser.add_argument("--precision", default=None, choices=("float32", "float64"),
                        help="per-frame mat-vec precision (default: the planner's default)")
    parser.add_argument("--against", default=None, metavar="REV",
                        help="also time the planner code of this git revision, side by side")
    parser.add_argument("--busy", action="store_true",
                        help="keep a second process spinning on the other core meanwhile")
    args = parser.parse_args(argv)

    print(_pin_one_core(), flush=True)
    spinner = _spin_other_core() if args.busy else None
    try:
        return _run(args)
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait()


def _spin_other_core() -> subprocess.Popen | None:
    """A process that keeps the next core busy (a Python loop) until it is killed."""
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    others = sorted(set(range(os.cpu_count() or 1)) - set(cores))
    if not others:
        print("--busy: no other core to keep busy", flush=True)
        return None
    code = f"import os; os.sched_setaffinity(0, {{{others[0]}}})\nwhile True: pass"
    print(f"a second process keeps core {others[0]} busy", flush=True)
    return subprocess.Popen([sys.executable, "-c", code])


def _run(args: argparse.Namespace) -> int:
    """The measurements of :func:`main` (see the module docstring)."""
    path = args.data or (str(DEV_COPY) if DEV_COPY.is_dir() else None)
    dataset = load_any(path)
    print(
        f"data: {len(dataset)} episodes, {dataset.n_frames} frames ({path or 'synthetic default'})",
        flush=True,
    )
    base = NonparametricConfig()
    if args.precision:
        base = replace(base, precision=args.precision)
    rng = np.random.default_rng(0)
    n_tracks = 2 if args.quick else 6
    tracks = [
        dataset[int(i)].receiver_xy for i in rng.choice(len(dataset), n_tracks, replace=False)
    ]
    print(f"replaying {n_tracks} recorded receiver tracks, {sum(len(t) for t in tracks)} frames; "
          f"precision {base.precision}, K = {base.top_k}, H = {base.horizon}", flush=True)

    t0 = time.perf_counter()
    ours = NonparametricAgent(replace(base, inducing_ratio=0.4)).fit(dataset)
    t1 = time.perf_counter()
    iaal = IAALAgent(base).fit(dataset)
    t2 = time.perf_counter()
    print(f"fit: ours {t1 - t0:.1f} s, IAAL {t2 - t1:.1f} s", flush=True)
    (ow, oc), (iw, ic) = _frame_costs([ours, iaal], tracks)
    print("\none streaming frame (update + predict), ours at inducing ratio 0.4 vs IAAL:")
    print(f"  ours  wall {_fmt(ow)}   cpu {_fmt(oc)}")
    print(f"  IAAL  wall {_fmt(iw)}   cpu {_fmt(ic)}")
    lengths = dataset.lengths.astype(np.float64)
    m = ours.bank.sizes.astype(np.float64)
    pred_var = float(np.sum(lengths**2) / np.sum(m**2))
    pred_mean = float(np.sum(lengths) / np.sum(m))
    print(
        f"  ratio IAAL/ours: wall {np.median(iw) / np.median(ow):.2f}x, cpu "
        f"{np.median(ic) / np.median(oc):.2f}x (medians)"
    )
    print(
        f"  predicted: variance mat-vec sum N_k^2 / sum M_k^2 = {pred_var:.2f}x, kernel + mean "
        f"sum N_k / sum M_k = {pred_mean:.2f}x; stored entries per query (with padding) "
        f"{iaal.bank.n_stored / ours.bank.n_stored:.2f}x ({iaal.bank.n_stored:,} vs "
        f"{ours.bank.n_stored:,})"
    )
    print(
        f"  200 Hz budget is 5 ms; ours uses {np.median(ow) / 5e-3:.0%} of it (wall median)",
        flush=True,
    )
    # The flows alone (FlowBank.predict at one query: kernel + mean + variance for every demo),
    # without the shared per-frame costs (cosine terms, top-K blend, Python calls).
    xs = np.concatenate(tracks)
    gp_cpu = []
    for a in (ours, iaal):
        a.bank.predict(xs[0] - a.origin)
        times = []
        for xy in xs:
            c0 = time.thread_time()
            a.bank.predict(xy - a.origin)
            times.append(time.thread_time() - c0)
        gp_cpu.append(times)
    go, gi = (np.median(g) for g in gp_cpu)
    print(
        f"  flows only (FlowBank.predict): ours {go * 1e3:.3f} ms, IAAL {gi * 1e3:.3f} ms cpu "
        "median, "
        f"ratio {gi / go:.2f}x; the rest of a frame costs ~{(np.median(oc) - go) * 1e3:.3f} ms "
        "for both",
        flush=True,
    )

    if args.against:
        with tempfile.TemporaryDirectory() as tmp:
            old_mod = _planner_of_revision(args.against, Path(tmp))
            old_cfg = old_mod.NonparametricConfig(**vars(replace(base, inducing_ratio=0.4)))
            old = old_mod.NonparametricAgent(old_cfg).fit(dataset)
            old_iaal = old_mod.NonparametricAgent(
                replace(old_cfg, exact=True, inducing_ratio=1.0)).fit(dataset)
            (nw, nc), (niw, nic), (pw, pc), (piw, pic) = _frame_costs(
                [ours, iaal, old, old_iaal], tracks)
            diff = 0.0
            for track in tracks:
                for a in (ours, old, iaal, old_iaal):
                    a.stream_reset()
                for xy in track:
                    for a, b in ((ours, old), (iaal, old_iaal)):
                        a.stream_update(xy)
                        b.stream_update(xy)
                        diff = max(diff, float(np.max(np.abs(a.stream_predict()
                                                             - b.stream_predict()))))
        print(f"\nthis code vs the planner of {args.against}, interleaved track by track:")
        print(f"  this  ours cpu {_fmt(nc)}   IAAL cpu {_fmt(nic)}")
        print(f"  {args.against:5s} ours cpu {_fmt(pc)}   IAAL cpu {_fmt(pic)}")
        print(f"  IAAL / ours (cpu medians): this {np.median(nic) / np.median(nc):.2f}x, "
              f"{args.against} {np.median(pic) / np.median(pc):.2f}x; ours {args.against}/this "
              f"{np.median(pc) / np.median(nc):.3f}x; largest chunk difference {diff:.1e} m",
              flush=True)

    print("\ncost per frame against the inducing ratio (IAAL = exact GP for reference):")
    print(
        f"  {'ratio':>5}  {'stored':>11}  {'wall median':>11}  {'wall p99':>9}  "
        f"{'cpu median':>10}  {'IAAL/this':>9}"
    )
    ratios = (0.1, 0.4, 1.0) if args.quick else RATIOS
    for r in ratios:
        agent = NonparametricAgent(replace(base, inducing_ratio=r)).fit(dataset)
        (w, c), (iw2, _) = _frame_costs([agent, iaal], tracks[:2] if args.quick else tracks[:3])
        print(f"  {r:5.1f}  {agent.bank.n_stored:11,}  {np.median(w) * 1e3:8.3f} ms  "
              f"{np.percentile(w, 99) * 1e3:6.3f} ms  {np.median(c) * 1e3:7.3f} ms  "
              f"{np.median(iw2) / np.median(w):8.2f}x", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
