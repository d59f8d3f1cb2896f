"""``train.py rl``: train a handover policy in the env with Stable-Baselines3 (PPO or SAC).

    python train.py rl --out runs/rl                        # PPO, residual on reactive, 2 envs
    python train.py rl --out runs/rl-scratch --form scratch
    python train.py rl --out runs/rl-sac --algo sac --base ours --data PATH
    python train.py rl --out runs/rl3 --seeds 0 1 2         # seeds in parallel (--backend ray)
    python train.py rl --out runs/rl --resume --steps 1500000 # extend a finished run
    python train.py rl --out /tmp/rl --quick                # a few hundred steps, for tests
    python train.py rl --out runs/rl-cv --base cv --use-sde --action-tau 0.1 --last-actions 1 \
        --privileged-critic --action-change 1 --contact-penalty 1   # the levers of docs/rl.md

The policy trains against the simulated person: scripted ID/OOD walkers with seeds from the
training range (every one above every closed-loop evaluation seed) and replays of the training
folds of Table I's split (never the held-out half the evaluation replays). ``--out`` holds the
checkpoint (``model.safetensors`` + ``config.json``; never SB3's pickled zip), ``train_log.csv``
and ``learning_curve.png`` (success rate, handover time and return against env steps on a fixed
set of training receivers), ``train_summary.json``; with several ``--seeds`` one folder
``seed-S`` each. Score it with ``evaluate.py closed-loop --agents reactive rl-residual
--rl-checkpoint runs/rl``.
"""

from __future__ import annotations

import argparse
import re
import time
from collections.abc import Callable
from pathlib import Path

from baselines.rl.config import QUICK, SENSING
from handover_env.paths import OUTPUT_LOCK, output_folder
from handover_eval.cli.args import (
    SEEDS,
    STEPS,
    WORKERS,
    add_backend_arguments,
    backend_from_args,
    int_in_range,
    positive_float,
)
from handover_eval.output_lock import OutputLock

#: The default budget: 58 min of the 2-core machine at the PPO rate measured with 2 envs, 287
#: env steps/s (229 with 1 env; docs/rl.md).
DEFAULT_STEPS = 1_000_000
DEFAULT_EVAL_EVERY = 50_000
ENVS = int_in_range(1, 64)
WIDTH = int_in_range(1, 4096)
_SEED_DIR = re.compile(r"seed-[0-9]+")


def add_rl_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``train.py rl``."""
    p.add_argument("--out", required=True, help="checkpoint folder (created); with several "
                   "--seeds, one sub-folder seed-S each")
    p.add_argument("--algo", choices=("ppo", "sac"), default="ppo",
                   help="SB3's PPO (default) or SAC")
    p.add_argument("--form", choices=("residual", "scratch"), default="residual",
                   help="residual: a bounded correction of the base agent's Cartesian target "
                   "(default); scratch: the policy's action is the target")
    p.add_argument("--base", choices=("reactive", "ours", "cv", "none"), default="reactive",
                   help="the residual's base agent (default reactive; ours = the SPGP planner "
                   "fitted on the training folds; cv = constant velocity); none = --form scratch")
    p.add_argument("--residual-xyz", type=positive_float, default=0.15,
                   help="m, bound of the residual's x/y/z correction (default 0.15)")
    p.add_argument("--residual-yaw", type=positive_float, default=0.3,
                   help="rad, bound of the residual's yaw correction (default 0.3)")
    p.add_argument("--steps", type=STEPS, default=None,
                   help=f"env steps of training, all envs together (default {DEFAULT_STEPS:,}: "
                   "about 60 min on the 2-core machine with 2 envs; "
                   f"{QUICK['steps']} with --quick)")
    p.add_argument("--envs", type=ENVS, default=None,
                   help="parallel envs per seed (SubprocVecEnv when > 1; default 2, 1 with "
                   "--quick)")
    p.add_argument("--seeds", type=SEEDS, nargs="+", default=[0],
                   help="training seeds; several train in parallel through --backend "
                   "(default 0)")
    p.add_argument("--workers", type=WORKERS, default=None,
                   help="seeds trained at once with several --seeds (default: one per core, "
                   "at most 2)")
    p.add_argument("--data", default=None, help="the dataset whose training folds are replayed: "
                   "a canonical .npz, a public-dataset folder, or omit for the synthetic default")
    p.add_argument("--folds", type=int_in_range(2, 100), default=None,
                   help="k of Table I's split; replays come from folds 0..k//2-1 only (default 10; "
                   "3 with --quick, as evaluate.py --quick)")
    p.add_argument("--split-seed", type=SEEDS, default=0,
                   help="seed of Table I's split (default 0, as evaluate.py)")
    p.add_argument("--p-replay", type=float, default=None,
                   help="probability that a training episode is a replay (default 0.2, 0 with "
                   "--quick; the rest ID 0.6 : OOD 0.2 walkers)")
    p.add_argument("--p-ood", type=float, default=0.2,
                   help="probability of an OOD walker (default 0.2; ID gets the rest)")
    p.add_argument("--lr", type=positive_float, default=3e-4, help="learning rate (default 3e-4)")
    p.add_argument("--net-arch", type=WIDTH, nargs="+", default=None,
                   help="hidden widths of the policy and value networks (default 64 64)")
    p.add_argument("--shaping", type=float, default=1.0,
                   help="weight of the potential-based shaping (reward per metre between the "
                   "bottle and the person's hand while held; default 1; 0 = HandoverReward alone)")
    p.add_argument("--sensing", default="randomized",
                   help=f"the env's sensing profile for training, one of {list(SENSING)} "
                   "(default randomized: sensor, controller and latency parameters drawn per "
                   "episode from their documented ranges; '' = the env's default, paper)")
    g = p.add_argument_group("levers (issue 36; docs/rl.md)")
    g.add_argument("--use-sde", action="store_true",
                   help="SB3's gSDE: time-correlated, state-dependent exploration (PPO, SAC)")
    g.add_argument("--sde-sample-freq", type=int_in_range(-1, 100_000), default=-1,
                   help="gSDE: steps between new noise matrices (-1: once a rollout, default)")
    g.add_argument("--action-noise", choices=("none", "pink"), default="none",
                   help="SAC: pink (1/f) noise added to the sampled action (default none)")
    g.add_argument("--noise-sigma", type=float, default=0.1,
                   help="standard deviation of --action-noise, action units (default 0.1)")
    g.add_argument("--action-tau", type=float, default=0.0,
                   help="s, time constant of the first-order filter the action reaches the robot "
                   "through (default 0: none)")
    g.add_argument("--last-actions", type=int_in_range(0, 30), default=0,
                   help="the policy also sees its last N actions (after the filter; default 0)")
    g.add_argument("--privileged-critic", action="store_true",
                   help="asymmetric actor-critic: the critic also sees the true person state and "
                   "wrist force; the actor only the sensed observation")
    g.add_argument("--warm-start", choices=("none", "reactive", "ours", "cv"), default="none",
                   help="scratch only: behaviour-clone the actor on this agent's actions first")
    g.add_argument("--warm-start-episodes", type=int_in_range(1, 10_000), default=None,
                   help="teacher episodes of --warm-start (default 50; 2 with --quick)")
    g.add_argument("--warm-start-epochs", type=int_in_range(1, 1000), default=20,
                   help="passes of the warm start's fit (default 20)")
    g.add_argument("--action-change", type=float, default=0.0,
                   help="weight of the penalty on the action's change per step (default 0)")
    g.add_argument("--contact-penalty", type=float, default=0.0,
                   help="weight of the penalty on body contact beyond the receiving hand, per "
                   "second at the region's ISO/TS 15066 limit (default 0)")
    p.add_argument("--eval-every", type=STEPS, default=None,
                   help=f"env steps between learning-curve points and checkpoints (default "
                   f"{DEFAULT_EVAL_EVERY:,})")
    p.add_argument("--curve-episodes", type=int_in_range(1, 1000), default=10,
                   help="fixed training receivers of the learning curve (default 10)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out (a larger "
                   "--steps extends it)")
    p.add_argument("--overwrite", action="store_true", help="replace the run in --out")
    p.add_argument("--quick", action="store_true",
                   help=f"a tiny run for tests: {QUICK['steps']} steps, 1 env, a 16x16 network, "
                   "walkers only, 2 curve receivers")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_backend_arguments(p)


def config_from_args(args: argparse.Namespace):
    """The :class:`baselines.rl.config.RLConfig` of the flags."""
    from baselines.rl.config import RLConfig

    p_replay = args.p_replay if args.p_replay is not None else (0.0 if args.quick else 0.2)
    if not (0 <= p_replay <= 1 and 0 <= args.p_ood <= 1 and p_replay + args.p_ood <= 1):
        raise ValueError("--p-replay and --p-ood must be in [0, 1] with a sum <= 1")
    form = "scratch" if args.base == "none" else args.form
    warm = "" if args.warm_start == "none" else args.warm_start
    episodes = 0 if not warm else args.warm_start_episodes or (2 if args.quick else 50)
    kw: dict = dict(algo=args.algo, form=form, base=args.base if form == "residual"
                    else "", use_sde=args.use_sde, sde_sample_freq=args.sde_sample_freq,
                    action_noise="" if args.action_noise == "none" else args.action_noise,
                    noise_sigma=args.noise_sigma, action_tau=args.action_tau,
                    last_actions=args.last_actions, privileged_critic=args.privileged_critic,
                    warm_start=warm, warm_start_episodes=episodes,
                    warm_start_epochs=args.warm_start_epochs, action_change=args.action_change,
                    contact_penalty=args.contact_penalty, residual_xyz=args.residual_xyz,
                    residual_yaw=args.residual_yaw,
                    n_envs=2, learning_rate=args.lr, shaping=args.shaping,
                    sensing=args.sensing, folds=args.folds or (3 if args.quick else 10),
                    split_seed=args.split_seed,
                    curve_episodes=args.curve_episodes, p_ood=args.p_ood,
                    p_replay=p_replay, p_id=1.0 - args.p_ood - p_replay,
                    steps=DEFAULT_STEPS, eval_every=DEFAULT_EVAL_EVERY)
    if args.quick:
        kw.update({k: v for k, v in QUICK.items() if k != "p_replay"})
    if args.net_arch is not None:
        kw["net_arch"] = tuple(args.net_arch)
    if args.steps is not None:
        kw["steps"] = args.steps
    if args.eval_every is not None:
        kw["eval_every"] = args.eval_every
    if args.envs is not None:
        kw["n_envs"] = args.envs
    return RLConfig(**kw)


def check_out(out: Path, seeds: list[int], resume: bool, overwrite: bool) -> None:
    """May the run write into ``out``? (one seed: the checkpoint rules of train.py; several: a
    folder of ``seed-S`` checkpoint folders.)"""
    from baselines.checkpoint_io import CheckpointError, check_out_dir
    from handover_eval.rl.output import SEEDS_PNG, SEEDS_SUMMARY

    if len(seeds) > 1 and out.is_dir():
        others = sorted(p.name for p in out.iterdir() if not _SEED_DIR.fullmatch(p.name)
                        and p.name not in (OUTPUT_LOCK, SEEDS_PNG, SEEDS_SUMMARY))
        if others:
            raise CheckpointError(f"--out {out} holds other files ({', '.join(others[:4])}); "
                                  "with several --seeds it holds only seed-S folders")
    from handover_eval.rl.run import seed_folders

    for folder in seed_folders(out, seeds):
        check_out_dir(folder, "rl", resume, overwrite)


def run_rl_command(args: argparse.Namespace, load_data: Callable) -> None:
    """``train.py rl``: check the flags and --out, load the data, train, write, print."""
    from dataclasses import replace

    from handover_eval.methods import default_workers
    from handover_eval.provenance import code_provenance
    from handover_eval.rl.output import write_summary
    from handover_eval.rl.report import summary
    from handover_eval.rl.run import run_training, seed_folders, training_data

    config = config_from_args(args)
    seeds = list(dict.fromkeys(args.seeds))
    out = output_folder(args.out, "--out")
    backend = backend_from_args(args)
    workers = args.workers or default_workers()
    with OutputLock(out):
        check_out(out, seeds, args.resume, args.overwrite)
        needs_data = config.p_replay > 0 or (config.form == "residual" and config.base == "ours"
                                             ) or config.warm_start == "ours"
        dataset = load_data(args.data, args.quick, 0) if needs_data else None
        data = replace(training_data(dataset, config), provenance=code_provenance(
            getattr(args, "argv", None)))
        print(f"[rl] {config.algo} {config.form}"
              f"{' on ' + config.base if config.form == 'residual' else ''}, {config.steps:,} "
              f"steps, {config.n_envs} env(s), seeds {seeds}; {len(data.replays)} training "
              f"replays (folds {list(data.folds)} of {config.folds}) of "
              f"{data.dataset or 'no dataset'}", flush=True)
        t0 = time.perf_counter()
        from handover_eval.backend import session

        with session(backend, workers):
            states = run_training(config, seeds, out, data, args.resume, workers,
                                  not args.no_progress)
        for seed, folder, state in zip(seeds, seed_folders(out, seeds), states, strict=True):
            write_summary(folder, state, config, {"seed": seed, "n_replays": len(data.replays)})
            print(f"[rl] seed {seed}: {summary(state)} -> {folder}")
        if len(seeds) > 1:
            from handover_eval.rl.output import write_seeds

            write_seeds(out, states, config)
        print(f"[rl] wrote {out}/ in {time.perf_counter() - t0:.0f} s")


def add_rl_parser(sub: argparse._SubParsersAction, load_data: Callable) -> None:
    """Add ``rl`` to train.py's sub-commands."""
    import functools

    sp = sub.add_parser("rl", help="RL in the env (SB3 PPO/SAC): a residual on a base agent or "
                        "from scratch, trained against the simulated person",
                        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_rl_arguments(sp)
    sp.set_defaults(func=functools.partial(run_rl_command, load_data=load_data), threads=1,
                    device="cpu")
