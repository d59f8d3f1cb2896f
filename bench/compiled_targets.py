"""What compiled per-step code would buy: the person's tick targets in numba, bit for bit.

Issue 22 asks for env cost / raw ``mj_step`` <= 1.3x; ``bench/env_overhead.py`` shows the env's
Python at ~0.9x raw physics, spread over ~1,100 small numpy and binding calls per env step, none
of them above ~0.07x. This benchmark measures, on one such piece, what moving the arithmetic out
of the interpreter gives: :meth:`handover_env.person.targets.BodyTargets.plan_ticks` (the step's
target interpolation, ~25 numpy calls on (S, 3) and (S, 4) arrays) and
:meth:`~handover_env.person.targets.BodyTargets.apply` (one tick's targets) written as loops
compiled by numba, with the same IEEE operations in the same order (no fast-math, no fused
multiply-add), run beside the numpy code on every env step of reactive-agent episodes. It prints
whether every output agreed bit for bit, both times per call and their ratio, and numba's
compile time (paid per process unless numba caches to disk).

numba is not a dependency of handover_env (it is not agreed; see bench/README.md):
without it the benchmark says so and exits 0. ``pip install numba`` into the venv to run it.

Usage: ``python bench/compiled_targets.py [--quick]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from handover_env.person.person import RATE  # noqa: E402


def compiled(njit):
    """The two kernels, compiled with ``njit`` (numba's, without fast-math)."""

    @njit(fastmath=False)
    def plan(q0, q1, o0, o1, vel_prev, lag_dt, gains, limits, quat0, dquat, pos0, dpos, vel):
        n = q0.shape[0]
        dt = 1.0 / RATE
        for s in range(n):
            w1, x1, y1, z1 = q1[s, 0], q1[s, 1], q1[s, 2], q1[s, 3]
            w0, x0, y0, z0 = q0[s, 0], q0[s, 1], q0[s, 2], q0[s, 3]
            dw = w1 * w0 - x1 * -x0 - y1 * -y0 - z1 * -z0
            sign = -1.0 if dw < 0 else 1.0
            fx = ((w1 * -x0 + x1 * w0 + y1 * -z0 - z1 * -y0) * sign) * lag_dt[s]
            fy = ((w1 * -y0 - x1 * -z0 + y1 * w0 + z1 * -x0) * sign) * lag_dt[s]
            fz = ((w1 * -z0 + x1 * -y0 - y1 * -x0 + z1 * w0) * sign) * lag_dt[s]
            a0 = w0 - fx * x0 - fy * y0 - fz * z0
            a1 = x0 + fx * w0 + fy * z0 - fz * y0
            a2 = y0 - fx * z0 + fy * w0 + fz * x0
            a3 = z0 + fx * y0 - fy * x0 + fz * w0
            quat0[s, 0], quat0[s, 1], quat0[s, 2], quat0[s, 3] = a0, a1, a2, a3
            dquat[s, 0] = (w1 - fx * x1 - fy * y1 - fz * z1) - a0
            dquat[s, 1] = (x1 + fx * w1 + fy * z1 - fz * y1) - a1
            dquat[s, 2] = (y1 - fx * z1 + fy * w1 + fz * x1) - a2
            dquat[s, 3] = (z1 + fx * y1 - fy * x1 + fz * w1) - a3
            v0 = (o1[s, 0] - o0[s, 0]) / dt
            v1 = (o1[s, 1] - o0[s, 1]) / dt
            v2 = (o1[s, 2] - o0[s, 2]) / dt
            c0 = (v0 - vel_prev[s, 0]) / dt
            c1 = (v1 - vel_prev[s, 1]) / dt
            c2 = (v2 - vel_prev[s, 2]) / dt
            sv = min(1.0, limits[s, 0] / max(np.sqrt((v0 * v0 + v1 * v1) + v2 * v2), 1e-12))
            sa = min(1.0, limits[n + s, 0] / max(np.sqrt((c0 * c0 + c1 * c1) + c2 * c2), 1e-12))
            gv, ga = gains[s, 0], gains[n + s, 0]
            for c, (v, a) in enumerate(((v0, c0), (v1, c1), (v2, c2))):
                dpos[s, c] = o1[s, c] - o0[s, c]
                vel[s, c] = v
                pos0[s, c] = (o0[s, c] + (v * sv) * gv) + (a * sa) * ga

    @njit(fastmath=False)
    def apply(dpos, pos0, dquat, quat0, a, mocap_pos, mocap_quat):
        for s in range(dpos.shape[0]):
            for c in range(3):
                mocap_pos[s, c] = dpos[s, c] * a + pos0[s, c]
            for c in range(4):
                mocap_quat[s, c] = dquat[s, c] * a + quat0[s, c]

    return plan, apply


def measure(episodes: int) -> dict[str, float]:
    """Both versions on every env step of ``episodes`` reactive episodes; times per call (s)."""
    import gymnasium as gym
    from numba import njit

    import handover_env  # noqa: F401
    from agents.reactive import ReactiveAgent

    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    targets = env.receiver.targets
    agent = ReactiveAgent()
    plan, apply = compiled(njit)
    clock = time.perf_counter
    res = {"steps": 0, "mismatches": 0, "plan_numpy": 0.0, "plan_numba": 0.0,
           "apply_numpy": 0.0, "apply_numba": 0.0}
    bufs: dict[str, np.ndarray] = {}
    numpy_plan = targets.plan_ticks

    def both(alphas: list[float]) -> None:
        (o0, q0), (o1, q1) = targets.key0, targets.key1
        n = len(o0)
        if not bufs:
            bufs.update({k: np.zeros((n, w)) for k, w in (
                ("quat0", 4), ("dquat", 4), ("pos0", 3), ("dpos", 3), ("vel", 3),
                ("mpos", 3), ("mquat", 4))})
        b = bufs
        vel_prev = targets._vel.copy()
        t = clock()
        plan(q0, q1, o0, o1, vel_prev, targets._lag_dt, targets._gains, targets._limits,
             b["quat0"], b["dquat"], b["pos0"], b["dpos"], b["vel"])
        res["plan_numba"] += clock() - t
        t = clock()
        numpy_plan(alphas)
        res["plan_numpy"] += clock() - t
        t = clock()
        apply(b["dpos"], b["pos0"], b["dquat"], b["quat0"], 0.5, b["mpos"], b["mquat"])
        res["apply_numba"] += clock() - t
        t = clock()
        targets.apply(env.data, 0.5)
        res["apply_numpy"] += clock() - t
        pairs = ((b["quat0"], targets._quat0), (b["dquat"], targets._dquat),
                 (b["pos0"], targets._pos0), (b["dpos"], targets._dpos), (b["vel"], targets._vel),
                 (b["mpos"], targets._mocap_pos), (b["mquat"], targets._mocap_quat))
        res["mismatches"] += sum(not np.array_equal(x, y) for x, y in pairs)
        res["steps"] += 1

    obs, _ = env.reset(seed=0)
    n = len(targets.key0[0])
    t = clock()  # compile on dummy arguments of the right types
    z3, z4 = np.zeros((n, 3)), np.zeros((n, 4))
    plan(z4, z4, z3, z3, z3, targets._lag_dt, targets._gains, targets._limits,
         z4.copy(), z4.copy(), z3.copy(), z3.copy(), z3.copy())
    apply(z3, z3, z4, z4, 0.5, z3.copy(), z4.copy())
    res["compile"] = clock() - t
    targets.plan_ticks = both
    for ep in range(episodes):
        obs, _ = env.reset(seed=ep, options={"receiver": "id" if ep % 2 == 0 else "ood"})
        agent.reset()
        while True:
            obs, _, term, trunc, _ = env.step(agent.act(obs))
            if term or trunc:
                break
    return res


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="2 episodes, not 10")
    args = parser.parse_args(argv)
    try:
        import numba
    except ImportError:
        print("compiled_targets: numba is not installed (not a dependency of handover_env); "
              "`pip install numba` into the venv to run this benchmark")
        return 0
    r = measure(2 if args.quick else 10)
    steps = r["steps"]
    print(f"person's tick targets, numpy vs numba {numba.__version__} (no fast-math), "
          f"{steps} env steps of reactive episodes")
    print(f"  outputs that differ in any bit: {r['mismatches']} of {7 * steps}")
    for key in ("plan", "apply"):
        a, b = r[f"{key}_numpy"] / steps, r[f"{key}_numba"] / steps
        print(f"  {key:<6} numpy {1e6 * a:7.1f} us  numba {1e6 * b:6.1f} us  ratio {a / b:5.1f}x")
    print(f"  numba compile time (once per process): {r['compile']:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
