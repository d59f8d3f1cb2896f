"""Where one physics step of the handover scene goes: robot alone, + person, + contacts, + welds.

The states are the env's own (``DynamicHandover-v0`` stepped by the reactive agent on ID and OOD
receivers, one ``mjSTATE_INTEGRATION`` snapshot per env step). From every snapshot each model
variant takes one env step of physics (``mj_step(m, d, 20)``, CPU time of this thread); the
variants take turns snapshot by snapshot, so they see the same machine load. Printed: us per
``mj_step`` and their ratios, MuJoCo's own timers (``mjData.timer``) per step, constraint rows
and contacts per step.

Variants (all from :func:`handover_env.robot.scene.build_spec`):

* ``robot``: the scene without the receiver (the spec with the receiver's bodies, welds and
  excludes deleted); the robot and object states are copied by joint name.
* ``+person``: the 13 segments, their joints and mocap targets, no collisions (geom contype and
  conaffinity 0), holding welds off: the person's bodies alone.
* ``+contacts``: the segments' geoms collide with the robot and the object as in the env.
* ``+welds``: the full scene as the env runs it.

Then, on the full scene: the ``mj_step`` entry points (20 calls of ``mj_step``, one call with
``nstep=20``, 20 x ``mj_step1`` + ``mj_step2``) and solver / option candidates for a cheaper
person, each with the largest state difference to the env's settings after one env step from
the same snapshots (so a setting that changes the physics shows it), and the timestep check:
1/300 s against the env's 1/600 s, free motion and a contact with the robot.

Usage: ``python bench/physics_breakdown.py [--quick]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import handover_env  # noqa: E402, F401
from agents.reactive import ReactiveAgent  # noqa: E402
from handover_env.envs.base_handover import FRAME_SKIP  # noqa: E402
from handover_env.person.body_model import PREFIX  # noqa: E402
from handover_env.robot.scene import build_spec  # noqa: E402

STATE = mujoco.mjtState.mjSTATE_INTEGRATION
TIMERS = ("STEP", "FORWARD", "POSITION", "POS_KINEMATICS", "POS_INERTIA", "POS_COLLISION",
          "COL_BROAD", "COL_NARROW", "POS_MAKE", "POS_PROJECT", "VELOCITY", "ACTUATION",
          "CONSTRAINT", "ADVANCE")


def _pin_one_core() -> str:
    try:
        cores = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cores[0]})
        return f"pinned to core {cores[0]} of {len(cores)} available"
    except (AttributeError, OSError):
        return "not pinned (no sched_setaffinity)"


def record_states(episodes: int, max_steps: int) -> tuple[mujoco.MjModel, list[np.ndarray]]:
    """The env's model and one integration state per env step of reactive-agent episodes."""
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    m, agent, states = env.model, ReactiveAgent(), []
    buf = np.empty(mujoco.mj_stateSize(m, STATE))
    for ep in range(episodes):
        obs, _ = env.reset(seed=ep, options={"receiver": ("id", "ood")[ep % 2]})
        agent.reset()
        for _ in range(max_steps):
            mujoco.mj_getState(m, env.data, buf, STATE)
            states.append(buf.copy())
            obs, _, term, trunc, _ = env.step(agent.act(obs))
            if term or trunc:
                break
    return m, states


def robot_only_model() -> mujoco.MjModel:
    """The scene without the receiver: its bodies (and targets), welds and excludes deleted."""
    spec = build_spec()
    for b in list(spec.worldbody.bodies):
        if b.name.startswith(PREFIX):
            spec.delete(b)
    for e in list(spec.equalities):
        if e.name.startswith(PREFIX):
            spec.delete(e)
    for x in list(spec.excludes):
        if x.bodyname1.startswith(PREFIX) or x.bodyname2.startswith(PREFIX):
            spec.delete(x)
    return spec.compile()


def state_mapper(src: mujoco.MjModel, dst: mujoco.MjModel):
    """A function setting ``dst``'s data from a ``src`` integration state, matched by name."""
    full = mujoco.MjData(src)
    pairs = []
    for j in range(dst.njnt):
        name = mujoco.mj_id2name(dst, mujoco.mjtObj.mjOBJ_JOINT, j)
        js = mujoco.mj_name2id(src, mujoco.mjtObj.mjOBJ_JOINT, name)
        nq = {0: 7, 1: 4}.get(int(dst.jnt_type[j]), 1)
        nv = {0: 6, 1: 3}.get(int(dst.jnt_type[j]), 1)
        pairs.append((dst.jnt_qposadr[j], src.jnt_qposadr[js], nq,
                      dst.jnt_dofadr[j], src.jnt_dofadr[js], nv))
    acts = [mujoco.mj_name2id(src, mujoco.mjtObj.mjOBJ_ACTUATOR,
                              mujoco.mj_id2name(dst, mujoco.mjtObj.mjOBJ_ACTUATOR, a))
            for a in range(dst.nu)]
    # Equalities in order, the receiver's left out (the gripper's own have no names).
    names = [mujoco.mj_id2name(src, mujoco.mjtObj.mjOBJ_EQUALITY, e) or "" for e in range(src.neq)]
    eqs = [e for e, name in enumerate(names) if not name.startswith(PREFIX)]
    if len(eqs) != dst.neq:
        raise RuntimeError(f"{len(eqs)} robot equalities in the scene, {dst.neq} without person")

    def apply(state: np.ndarray, d: mujoco.MjData) -> None:
        mujoco.mj_setState(src, full, state, STATE)
        for qd, qs, nq, vd, vs, nv in pairs:
            d.qpos[qd:qd + nq] = full.qpos[qs:qs + nq]
            d.qvel[vd:vd + nv] = full.qvel[vs:vs + nv]
            d.qacc_warmstart[vd:vd + nv] = full.qacc_warmstart[vs:vs + nv]
        d.ctrl[:] = full.ctrl[acts]
        d.act[:] = full.act[: dst.na] if dst.na else d.act
        d.eq_active[:] = full.eq_active[eqs]
        d.time = full.time

    return apply


def _timers(d: mujoco.MjData) -> np.ndarray:
    return np.array([d.timer[getattr(mujoco.mjtTimer, "mjTIMER_" + t)].duration for t in TIMERS])


def _reset_timers(d: mujoco.MjData) -> None:
    for t in TIMERS:
        d.timer[getattr(mujoco.mjtTimer, "mjTIMER_" + t)].duration = 0.0
        d.timer[getattr(mujoco.mjtTimer, "mjTIMER_" + t)].number = 0


def breakdown(full: mujoco.MjModel, states: list[np.ndarray]) -> None:
    """us per mj_step and MuJoCo's timers of the four variants, interleaved per snapshot."""
    ids_geoms = [g for g in range(full.ngeom)
                 if mujoco.mj_id2name(full, mujoco.mjtObj.mjOBJ_GEOM, g) and mujoco.mj_id2name(
                     full, mujoco.mjtObj.mjOBJ_GEOM, g).startswith(PREFIX)]
    welds = [e for e in range(full.neq)
             if (mujoco.mj_id2name(full, mujoco.mjtObj.mjOBJ_EQUALITY, e) or "").startswith(PREFIX)]
    robot = robot_only_model()
    person = full.__copy__()
    person.geom_contype[ids_geoms] = 0
    person.geom_conaffinity[ids_geoms] = 0
    variants = {"robot": (robot, state_mapper(full, robot), False),
                "+person": (person, None, True), "+contacts": (full, None, True),
                "+welds": (full, None, False)}
    data = {k: mujoco.MjData(v[0]) for k, v in variants.items()}
    cpu = dict.fromkeys(variants, 0.0)
    timers = {k: np.zeros(len(TIMERS)) for k in variants}
    nefc = {k: [] for k in variants}
    ncon = {k: [] for k in variants}
    for s in states:
        for k, (m, mapper, welds_off) in variants.items():
            d = data[k]
            if mapper is None:
                mujoco.mj_setState(m, d, s, STATE)
            else:
                mapper(s, d)
            if welds_off:
                d.eq_active[welds] = 0
            _reset_timers(d)
            t = time.thread_time()
            mujoco.mj_step(m, d, FRAME_SKIP)
            cpu[k] += time.thread_time() - t
            timers[k] += _timers(d)
            nefc[k].append(d.nefc)
            ncon[k].append(d.ncon)
    n = len(states) * FRAME_SKIP
    print(f"\n{len(states)} env-step snapshots x {FRAME_SKIP} physics steps per variant")
    print(f"  {'variant':10s} {'nbody':>5} {'nv':>3} {'neq':>3} {'ngeom':>5} {'nefc':>5} "
          f"{'ncon':>5} {'us/step':>8} {'x robot':>8} {'real time':>9}")
    for k, (m, _, _) in variants.items():
        us = cpu[k] / n * 1e6
        print(f"  {k:10s} {m.nbody:5d} {m.nv:3d} {m.neq:3d} {m.ngeom:5d} {np.mean(nefc[k]):5.1f} "
              f"{np.mean(ncon[k]):5.2f} {us:8.2f} {cpu[k] / cpu['robot']:7.2f}x "
              f"{m.opt.timestep * 1e6 / us:8.1f}x")
    # The timers include the timer callback's own cost: shown as shares of mjTIMER_STEP, and as
    # us per step of the measured CPU time split in those shares.
    print("\n  MuJoCo timers, share of mjTIMER_STEP (us per step of the measured time):")
    print("  " + f"{'timer':16s}" + "".join(f"{k:>16s}" for k in variants))
    for i, t in enumerate(TIMERS[1:], start=1):
        cells = []
        for k in variants:
            share = timers[k][i] / timers[k][0]
            cells.append(f"{share:6.1%} ({share * cpu[k] / n * 1e6:5.1f})")
        print("  " + f"{t:16s}" + "".join(f"{c:>16s}" for c in cells))


def entry_points(m: mujoco.MjModel, states: list[np.ndarray]) -> None:
    """20 x mj_step, mj_step(nstep=20), 20 x (mj_step1 + mj_step2): same states, same results."""
    def loop(mm, d):
        for _ in range(FRAME_SKIP):
            mujoco.mj_step(mm, d)

    def nstep(mm, d):
        mujoco.mj_step(mm, d, FRAME_SKIP)

    def split(mm, d):
        for _ in range(FRAME_SKIP):
            mujoco.mj_step1(mm, d)
            mujoco.mj_step2(mm, d)

    fns = {"20 x mj_step": loop, "mj_step(nstep=20)": nstep, "20 x mj_step1+2": split}
    data = {k: mujoco.MjData(m) for k in fns}
    cpu = dict.fromkeys(fns, 0.0)
    diff = dict.fromkeys(fns, 0.0)
    for s in states:
        ref = None
        for k, f in fns.items():
            d = data[k]
            mujoco.mj_setState(m, d, s, STATE)
            t = time.thread_time()
            f(m, d)
            cpu[k] += time.thread_time() - t
            q = np.concatenate([d.qpos, d.qvel])
            ref = q if ref is None else ref
            diff[k] = max(diff[k], float(np.max(np.abs(q - ref))))
    n = len(states) * FRAME_SKIP
    print("\nmj_step entry points on the full scene:")
    base = cpu["mj_step(nstep=20)"]
    for k in fns:
        print(f"  {k:20s} {cpu[k] / n * 1e6:7.2f} us/step  ({cpu[k] / base:.3f}x nstep)  "
              f"max state diff {diff[k]:.1e}")


def candidates(m: mujoco.MjModel, states: list[np.ndarray]) -> None:
    """Solver and option settings against the env's, same snapshots, with state agreement."""
    D = mujoco.mjtDisableBit

    def variant(flags: int = 0, **opt) -> mujoco.MjModel:
        mm = m.__copy__()
        for key, val in opt.items():
            setattr(mm.opt, key, val)
        mm.opt.disableflags |= flags
        return mm

    models = {
        "env settings": m,
        "jacobian sparse": variant(jacobian=mujoco.mjtJacobian.mjJAC_SPARSE),
        "jacobian auto": variant(jacobian=mujoco.mjtJacobian.mjJAC_AUTO),
        "islands off": variant(D.mjDSBL_ISLAND),
        "tolerance 1e-6": variant(tolerance=1e-6),
        "iterations 10": variant(iterations=10, ls_iterations=10),
        "solver CG": variant(solver=mujoco.mjtSolver.mjSOL_CG),
        "solver PGS": variant(solver=mujoco.mjtSolver.mjSOL_PGS),
        "cone pyramidal": variant(cone=mujoco.mjtCone.mjCONE_PYRAMIDAL),
        "no warmstart": variant(D.mjDSBL_WARMSTART),
    }
    data = {k: mujoco.MjData(v) for k, v in models.items()}
    cpu = dict.fromkeys(models, 0.0)
    diff = dict.fromkeys(models, 0.0)
    iters = {k: [] for k in models}
    for s in states:
        ref = None
        for k, mm in models.items():
            d = data[k]
            mujoco.mj_setState(mm, d, s, STATE)
            t = time.thread_time()
            mujoco.mj_step(mm, d, FRAME_SKIP)
            cpu[k] += time.thread_time() - t
            iters[k].append(int(d.solver_niter[0]))
            q = np.concatenate([d.qpos, d.qvel])
            ref = q if ref is None else ref
            diff[k] = max(diff[k], float(np.max(np.abs(q - ref))))
    n = len(states) * FRAME_SKIP
    print("\nsolver / option candidates on the full scene (same snapshots, one env step each):")
    print(f"  {'setting':18s} {'us/step':>8} {'env/this':>9} {'iters':>6}  max |dqpos, dqvel|")
    for k in models:
        print(f"  {k:18s} {cpu[k] / n * 1e6:8.2f} {cpu['env settings'] / cpu[k]:8.3f}x "
              f"{np.mean(iters[k]):6.2f}  {diff[k]:.1e}")


def _contact_force(m: mujoco.MjModel, d: mujoco.MjData) -> float:
    f6 = np.zeros(6)
    total = 0.0
    for i in range(d.ncon):
        mujoco.mj_contactForce(m, d, i, f6)
        total += f6[0]
    return total


def timestep_check(m: mujoco.MjModel, states: list[np.ndarray], seconds: float = 0.2) -> None:
    """Free motion and a robot-person contact at dt = 1/300 s against the env's 1/600 s."""
    coarse = m.__copy__()
    coarse.opt.timestep = 2 * m.opt.timestep
    d1, d2 = mujoco.MjData(m), mujoco.MjData(coarse)
    seg = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, PREFIX + "torso")
    root = m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, PREFIX + "root")]
    mocap = [m.body_mocapid[b] for b in range(m.nbody) if m.body_mocapid[b] >= 0
             and mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b).startswith(PREFIX)]
    tcp = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "ur5e/gripper/pinch")
    steps = int(round(seconds / m.opt.timestep))
    walk = np.array([0.0, 0.4, 0.0])  # m/s: the person walks into the gripper
    free_err, peak_fine, peak_coarse, mean_err = [], [], [], []
    for s in states[:: max(1, len(states) // 12)]:
        for contact in (False, True):
            for d, mm in ((d1, m), (d2, coarse)):
                mujoco.mj_setState(m, d, s, STATE)
                if contact:  # the torso 20 cm beside the gripper, targets moved along
                    mujoco.mj_forward(m, d)
                    shift = d.site_xpos[tcp] - d.xpos[seg] + np.array([0.0, -0.20, 0.0])
                    d.qpos[root:root + 3] += shift
                    d.mocap_pos[mocap] += shift
                    d.qvel[:] = 0.0
                mujoco.mj_forward(mm, d)
            forces = ([], [])
            for k in range(steps):
                if contact:
                    d1.mocap_pos[mocap] += walk * m.opt.timestep
                mujoco.mj_step(m, d1)
                if k % 2 == 1:
                    if contact:
                        d2.mocap_pos[mocap] += walk * coarse.opt.timestep
                    mujoco.mj_step(coarse, d2)
                    forces[0].append(_contact_force(m, d1))
                    forces[1].append(_contact_force(coarse, d2))
            if contact:
                f = np.array(forces)
                peak_fine.append(f[0].max())
                peak_coarse.append(f[1].max())
                mean_err.append(np.mean(np.abs(f[1] - f[0])) / max(np.mean(f[0]), 1e-9))
            else:
                free_err.append(float(np.max(np.abs(d2.xpos - d1.xpos))))
    print(f"\ntimestep 1/300 s vs the env's 1/600 s over {seconds} s from "
          f"{len(free_err)} snapshots:")
    print(f"  free motion: largest body position difference {max(free_err) * 1e3:.2f} mm")
    pf, pc = np.array(peak_fine), np.array(peak_coarse)
    touch = (pf > 0) & (pc > 0)  # a ratio only where both steps touched
    ratio = pc[touch] / pf[touch]
    ratios = (f"median ratio {np.median(ratio):.3f}, worst {np.max(np.abs(ratio - 1)):.1%} off "
              f"({touch.sum()} of {touch.size} snapshots touch at both steps)" if touch.any()
              else f"no snapshot touches at both steps ({touch.size} tried)")
    print(f"  the person walking into the gripper at 0.4 m/s: peak normal force "
          f"{np.median(pf):.1f} N (1/600) vs {np.median(pc):.1f} N (1/300), {ratios}; "
          f"mean |force difference| / mean force {np.median(mean_err):.1%} (median), "
          f"{np.max(mean_err):.1%} (worst)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer episodes")
    args = parser.parse_args(argv)
    print(_pin_one_core(), flush=True)
    m, states = record_states(2 if args.quick else 6, 150 if args.quick else 400)
    print(f"mujoco {mujoco.__version__}; the full scene: dt {m.opt.timestep:.6f} s, "
          f"jacobian {mujoco.mjtJacobian(m.opt.jacobian).name}, "
          f"solver {mujoco.mjtSolver(m.opt.solver).name}, cone {mujoco.mjtCone(m.opt.cone).name}",
          flush=True)
    breakdown(m, states)
    entry_points(m, states)
    candidates(m, states)
    timestep_check(m, states)
    return 0


if __name__ == "__main__":
    sys.exit(main())
