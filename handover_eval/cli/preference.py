"""``train.py preference`` and ``train.py preference-check``: arguments and the runs behind them.

Kept apart from ``train.py`` so that the script stays thin; nothing heavy is imported before the
arguments are parsed (``--help`` is instant).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from handover_env.paths import output_folder
from handover_eval.backend import (
    JobError,
    session,
)
from handover_eval.cli.args import (
    ITERATIONS,
    PARTICIPANTS,
    SEEDS,
    WALKS,
    add_backend_arguments,
    add_sensing_argument,
    backend_from_args,
    theta_grid,
)
from handover_eval.output_lock import OutputLock

PREFERENCE_HELP = """CoSpar (paper Sec. IV-B, V-B-1) tunes Theta = {K, B, t_f, f_r} over the paper's
ranges from a simulated participant (agents/participants.py) who walks past the robot in the env
and judges what happened: each iteration CoSpar proposes Theta, each is run as real episodes on
the participant's walks, the participant states preferences (paper Eq. 2 noise), the Laplace
posterior is updated. Prints Theta-hat beside the paper's and writes theta_hat.json, history.csv,
preferences.csv, participants.csv and posterior_marginals.png. Results come from simulated
participants, not people."""

CHECK_HELP = """Acceptance check: for each participant, brute-force their utility over a small grid
of Theta (episodes cached in OUT/episodes.jsonl), run CoSpar on the same grid for 20 iterations
and report the share of the achievable gain over a random Theta that its Theta-hat reaches (pass
at >= 90 %)."""


def add_preference_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``train.py preference``."""
    who = p.add_mutually_exclusive_group()
    who.add_argument(
        "--participant",
        type=SEEDS,
        default=None,
        metavar="SEED",
        help="the simulated participant (agents/participants.py) drawn with this seed (default 0)",
    )
    who.add_argument(
        "--participants",
        type=PARTICIPANTS,
        default=None,
        metavar="N",
        help="pool N participants (population seed --population-seed, 75%% male as in the "
        "paper) into one posterior, each making one step per iteration",
    )
    p.add_argument(
        "--population-seed",
        type=SEEDS,
        default=0,
        help="seed of the population for --participants (participant i has seed 1000*S+i)",
    )
    p.add_argument(
        "--iterations", type=ITERATIONS, default=20, help="CoSpar iterations (paper: 20)"
    )
    p.add_argument("--walks", type=WALKS, default=3,
                   help="episodes (walks of the participant) per proposed Theta (default 3)")
    p.add_argument(
        "--agent",
        choices=("ours", "reactive"),
        default="ours",
        help="the planner whose Theta is tuned (default ours: SPGP fitted on the synthetic "
        "default)",
    )
    p.add_argument("--receiver", choices=("id", "ood", "replay"), default="id",
                   help="id/ood: scripted walkers with the participant's body; replay: synthetic "
                        "demonstrations nearest their speed, at their height (default id)")
    p.add_argument(
        "--grid",
        type=theta_grid,
        default=(7, 6, 6, 7),
        metavar="NK,NB,NT,NF",
        help="CoSpar grid points per parameter over the paper's ranges (default 7,6,6,7)",
    )
    p.add_argument("--seed", type=SEEDS, default=0, help="seed of CoSpar's Thompson samples")
    p.add_argument(
        "--out",
        default=None,
        help="output folder (default results/preference/participant-SEED "
        "or results/preference/pooled-N)",
    )
    p.add_argument("--no-progress", action="store_true", help="no tqdm bar")
    add_sensing_argument(p)
    add_backend_arguments(p)


def add_check_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``train.py preference-check``."""
    p.add_argument(
        "--participants", type=PARTICIPANTS, default=4, help="participants checked (default 4)"
    )
    p.add_argument("--population-seed", type=SEEDS, default=1,
                   help="their population seed (default 1: not the study's population 0)")
    p.add_argument("--grid", type=theta_grid, default=(3, 3, 3, 3), metavar="NK,NB,NT,NF",
                   help="the brute-forced grid, also CoSpar's (default 3,3,3,3 = 81 Theta)")
    p.add_argument("--walks", type=WALKS, default=3, help="walks per Theta (default 3)")
    p.add_argument(
        "--iterations", type=ITERATIONS, default=20, help="CoSpar iterations (default 20)"
    )
    p.add_argument("--seed", type=SEEDS, default=0, help="seed of CoSpar's Thompson samples")
    p.add_argument(
        "--out", default="results/preference/check", help="output folder (episode cache, tables)"
    )
    p.add_argument("--no-progress", action="store_true", help="no tqdm bars")
    add_sensing_argument(p)


def run_preference_command(args: argparse.Namespace) -> None:
    """``train.py preference``: CoSpar on the env against one participant or a pooled group."""
    from agents.cospar import CoSparConfig
    from agents.participants import sample_participant, sample_population
    from handover_eval.preference.tuning import PAPER_THETA, PreferenceConfig, run_preference
    from handover_eval.preference.tuning_report import save_run, theta_line

    if args.participants is not None:
        participants = sample_population(args.participants, args.population_seed)
        default_out = Path("results/preference") / f"pooled-{args.participants}"
    else:
        seed = 0 if args.participant is None else args.participant
        participants = [sample_participant(seed)]
        default_out = Path("results/preference") / f"participant-{seed}"
    out = output_folder(args.out, "--out") if args.out is not None else default_out
    try:
        backend = backend_from_args(args)
    except RuntimeError as exc:  # Ray missing: train.py's one-line error
        raise ValueError(str(exc)) from None
    config = PreferenceConfig(
        iterations=args.iterations,
        walks=args.walks,
        agent=args.agent,
        receiver=args.receiver,
        sensing=args.sensing,
        cospar=CoSparConfig(points_per_dim=args.grid),
        seed=args.seed,
    )
    with OutputLock(out):  # held from before the run until its files are written
        for p in participants:
            b = p.body
            print(
                f"participant {p.pid}: {b.sex}, {b.height:.2f} m, walks {b.speed:.2f} m/s, "
                f"passes at y = {b.pass_y:.2f} m"
            )
        try:  # on Ray, each turn's new walks run as parallel tasks (handover_eval.preference.batch)
            with session(backend, max(1, min(2, os.cpu_count() or 1))) as sess:
                result = run_preference(participants, config, progress=not args.no_progress)
        except (JobError, ConnectionError) as exc:
            print(f"train.py: error: {exc}", file=sys.stderr)
            raise SystemExit(1) from None
        if sess.started_here:
            print(f"Ray start-up {sess.startup_s:.1f} s (not in the wall time below)")
        paths = save_run(result, participants, config, out)
    print(
        f"Θ̂ (argmax of the posterior mean over the tried actions): {theta_line(result.theta_hat)}"
    )
    print(
        "    argmax over the whole grid:                          "
        f"{theta_line(result.theta_hat_grid)}"
    )
    print(
        "    the paper's Θ̂ (real participants):                  "
        f"{theta_line(_params(PAPER_THETA))}"
    )
    print(
        f"{len(result.preferences)} preferences, {result.episodes} episodes "
        f"({result.episode_seconds:.0f} s), "
        f"{result.seconds:.0f} s wall, {result.seconds / config.iterations:.1f} s per iteration"
    )
    print("wrote " + ", ".join(str(p) for p in paths))


def _params(values):
    from handover_env.config import HandoverParams

    return HandoverParams(*values)


def run_check_command(args: argparse.Namespace) -> None:
    """``train.py preference-check``: does CoSpar find a brute-forced optimum?"""
    from handover_eval.preference.check import CheckConfig, run_check

    config = CheckConfig(
        participants=args.participants,
        population_seed=args.population_seed,
        grid=args.grid,
        walks=args.walks,
        iterations=args.iterations,
        seed=args.seed,
        sensing=args.sensing,
    )
    out = output_folder(args.out, "--out")
    with OutputLock(out):
        run_check(config, out, progress=not args.no_progress)
