"""Train the learned baselines: BC-MLP (torch) and ACT (LeRobot's ACTPolicy).

    python train.py bc-mlp --data PATH --out runs/bc_mlp
    python train.py act    --data PATH --out runs/act
    python train.py act    --smoke --out /tmp/act_smoke          # seconds, for tests
    python train.py preference --participant 0 --iterations 20   # CoSpar tunes Theta from a
    simulated participant
    python train.py preference --participants 8                  # ... pooled over 8 participants
    python train.py preference-check                             # CoSpar vs a brute-forced optimum
    python train.py rl --out runs/rl                             # SB3 PPO in the env (residual)

PATH is a canonical ``.npz`` (``handover-data convert``/``synth``), a folder of the
public dataset's pickles, or omitted for the embedded synthetic default. The checkpoint folder
(``--out``) holds safetensors weights plus JSON config and is loaded by ``BCMLPAgent.load(dir)`` /
``ACTAgent.load(dir)``; ``--resume`` continues an interrupted or finished run from it (with more
``--epochs`` / ``--steps`` to extend it). A folder that already holds a run is never silently
overwritten: pass ``--resume`` or ``--overwrite``; a folder of other files is refused. A running
command locks its ``--out`` (``handover_eval.output_lock``): a second run on it is refused. Bad
input gives a one-line error naming the file or option (exit status 2). ``--test-fold K``
holds out fold K of a stratified ``--folds``-fold split (by ID/OOD) from training and reports the
open-loop RMS on it at the end. Features: see ``handover_env/data/features.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from handover_env.offline import hub_offline
from handover_env.paths import output_folder
from handover_eval.cli.args import (
    EPOCHS,
    FOLDS,
    FRAMES,
    SEEDS,
    STEPS,
    fraction,
    int_in_range,
    positive_float,
)
from handover_eval.output_lock import OutputLock
from handover_eval.reporting import write_text

if TYPE_CHECKING:  # heavy imports happen after argument parsing, so --help is instant
    from handover_env.data.dataset import HandoverDataset

SMOKE_EPISODES = 24
#: Bounds of the integer options (argparse errors name the option and state the range).
THREADS = int_in_range(1, 256)
WIDTH = int_in_range(1, 65_536)  # --hidden, --dim-model, --dim-feedforward
LAYERS = int_in_range(1, 128)


# ---------------------------------------------------------------------------- data
def load_data(path: str | None, smoke: bool, seed: int) -> HandoverDataset:
    """The training demonstrations: .npz, public folder, or the synthetic default."""
    import numpy as np

    from handover_env.data.dataset import HandoverDataset
    try:
        from handover_env.person.demos import load_any
    except ImportError:
        load_any = None
    if path is None and smoke:
        from handover_env.person.synthetic import generate_synthetic

        return generate_synthetic(n=SMOKE_EPISODES, ood_fraction=0.125, seed=seed)
    if load_any is not None:
        data = load_any(path)
    elif path is None:
        from handover_env.person.synthetic import generate_synthetic

        data = generate_synthetic(n=1000, ood_fraction=0.1, seed=0)
    elif Path(path).is_dir():
        from handover_env.data.public import load_public_dataset

        data = load_public_dataset(path)
    else:
        data = HandoverDataset.load(path)
    if smoke and len(data) > SMOKE_EPISODES:
        data = data.subset(np.linspace(0, len(data) - 1, SMOKE_EPISODES).round().astype(int))
    return data


def split_test(data: HandoverDataset, folds: int, test_fold: int | None, seed: int):
    """(train_data, test_data or None): hold out one stratified fold for the final RMS."""
    if test_fold is None:
        return data, None
    if not 0 <= test_fold < folds:
        raise ValueError(f"--test-fold must be in [0, {folds - 1}], got {test_fold}")
    train_idx, test_idx = data.stratified_kfold(folds, seed=seed)[test_fold]
    return data.subset(train_idx), data.subset(test_idx)


# ---------------------------------------------------------------------------- evaluation
def openloop_rms(agent, test: HandoverDataset) -> dict:
    """Open-loop RMS (mm, 3D and per axis; mean +- std over episodes, ID and OOD apart) on ``test``
    by the shared protocol (``handover_eval.openloop.protocol``: a query at every frame from
    frame 5, horizon 30, row 0 = the current frame). The protocol calls ``predict_episode``, through
    which the baselines also read the giver position at the query frame (their
    ``observation.state``)."""
    from handover_eval.openloop.protocol import OpenLoopProtocol, evaluate_openloop, summarise

    return summarise(
        evaluate_openloop(agent, test, OpenLoopProtocol(horizon=agent.horizon), progress=False)
    )


def report(
    name: str, agent, test: HandoverDataset | None, out: Path, t0: float, val_loss: float
) -> None:
    import torch

    summary = {"method": name, "wall_time_s": time.perf_counter() - t0, "final_val_loss": val_loss,
               "threads": torch.get_num_threads(), "loadavg": os.getloadavg()}
    print(f"[{name}] wall time {summary['wall_time_s']:.1f} s, best validation loss {val_loss:.5f}")
    if test is not None:
        summary["test_rms_mm"] = openloop_rms(agent, test)
        for split, r in summary["test_rms_mm"].items():
            print(
                f"[{name}] held-out {split} (n={r['n_episodes']}): RMS 3D {r['rms_3d_mm']:.2f} +- "
                f"{r['rms_3d_std']:.2f} mm, per axis {r['rms_axis_mm']:.2f} +- "
                f"{r['rms_axis_std']:.2f} mm"
            )
    write_text(json.dumps(summary, indent=1), out / "train_summary.json")


# ---------------------------------------------------------------------------- commands
def _default(value, default):
    """``value`` unless the option was not given (None); 0 is a value, not "unset"."""
    return default if value is None else value


def train_bc_mlp(args: argparse.Namespace) -> None:
    from baselines.bc_mlp import BCMLPAgent, BCMLPConfig
    from baselines.checkpoint_io import check_out_dir

    cfg = BCMLPConfig(
        history=args.history, horizon=args.horizon,
        hidden=tuple(_default(args.hidden, [64, 64] if args.smoke else [256, 256, 256])),
        lr=_default(args.lr, 1e-3), batch_size=_default(args.batch_size, 256),
        max_epochs=_default(args.epochs, 3 if args.smoke else 50), patience=args.patience,
        val_fraction=args.val_fraction, seed=args.seed, device=args.device,
        use_giver_state=args.giver_state,
    )
    out = output_folder(args.out, "--out")
    with OutputLock(out):
        check_out_dir(out, "bc_mlp", args.resume, args.overwrite)
        data = load_data(args.data, args.smoke, args.seed)
        train, test = split_test(data, args.folds, args.test_fold, args.seed)
        print(f"[bc-mlp] {len(train)} training episodes ({train.n_frames} frames), config {cfg}")
        t0 = time.perf_counter()
        agent = BCMLPAgent(cfg).fit(
            train, out_dir=out, resume=args.resume, progress=not args.no_progress, log=print
        )
        report("bc-mlp", agent, test, out, t0, agent.train_log["best_val"])


def train_act(args: argparse.Namespace) -> None:
    from baselines.act import ACTAgent, ACTAgentConfig
    from baselines.checkpoint_io import check_out_dir

    policy = (
        dict(dim_model=32, n_heads=2, dim_feedforward=64, n_encoder_layers=1, latent_dim=4)
        if args.smoke
        else {}
    )
    for key in ("dim_model", "n_heads", "dim_feedforward", "n_encoder_layers", "n_decoder_layers"):
        if getattr(args, key) is not None:
            policy[key] = getattr(args, key)
    if args.no_vae:
        policy["use_vae"] = False
    if args.lr is not None:
        policy["optimizer_lr"] = args.lr
    cfg = ACTAgentConfig(
        history=args.history, horizon=args.horizon, paper_scale=args.paper_scale, policy=policy,
        batch_size=_default(args.batch_size, 16 if args.smoke else 64),
        steps=_default(args.steps, 20 if args.smoke else 8_000),
        eval_every=_default(args.eval_every, 10 if args.smoke else 1_000),
        val_fraction=args.val_fraction, seed=args.seed, device=args.device,
        use_giver_state=args.giver_state,
    )
    out = output_folder(args.out, "--out")
    export_root = (
        output_folder(args.export_root, "--export-root")
        if args.export_root is not None
        else out / "lerobot_dataset"
    )
    with OutputLock(out):
        check_out_dir(out, "act", args.resume, args.overwrite)
        data = load_data(args.data, args.smoke, args.seed)
        train, test = split_test(data, args.folds, args.test_fold, args.seed)
        print(f"[act] {len(train)} training episodes ({train.n_frames} frames), config {cfg}")
        t0 = time.perf_counter()
        agent = ACTAgent(cfg).fit(
            train, out_dir=out, export_root=export_root, resume=args.resume,
            progress=not args.no_progress, log=print,
            rebuild_export=args.overwrite or args.export_root is None,
        )
        report("act", agent, test, out, t0, agent.train_log["best_val"])


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="train.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = p.add_subparsers(
        dest="method", required=True, metavar="{bc-mlp,act,preference,preference-check,rl}"
    )

    def common(sp: argparse.ArgumentParser) -> None:
        sp.add_argument(
            "--data",
            default=None,
            help="a canonical .npz, a public-dataset folder, or omit for "
            "the embedded synthetic default (1000 episodes, 10%% OOD)",
        )
        sp.add_argument(
            "--out", required=True, help="checkpoint folder (created; safetensors + JSON config)"
        )
        sp.add_argument(
            "--resume",
            action="store_true",
            help="continue training from the state saved in --out "
            "(a finished run is extended by a larger --epochs / --steps)",
        )
        sp.add_argument(
            "--overwrite",
            action="store_true",
            help="replace the run already in --out (its "
            "checkpoint files only; a folder of other files is always refused), and rebuild an "
            "--export-root that holds other data",
        )
        sp.add_argument("--smoke", action="store_true", help=f"tiny fast configuration for tests: "
                        f"{SMOKE_EPISODES} episodes, a few epochs/steps, a small network")
        sp.add_argument(
            "--seed", type=SEEDS, default=0, help="seed of initialisation, sampling and splits"
        )
        sp.add_argument("--device", default="cpu", help="torch device (default cpu)")
        sp.add_argument(
            "--threads",
            type=THREADS,
            default=1,
            help="torch CPU threads (default 1: on a "
            "shared 2-core machine 2 threads oversubscribe and run ~10x slower; ACT always trains "
            "on one, so that a seed gives the same weights)",
        )
        sp.add_argument("--batch-size", type=int_in_range(1, 1_000_000), default=None,
                        help="samples per step (default 256 for bc-mlp, 64 for act)")
        sp.add_argument("--lr", type=positive_float, default=None,
                        help="learning rate (default 1e-3 bc-mlp, 1e-4 act)")
        sp.add_argument("--history", type=FRAMES, default=10,
                        help="W, frames of receiver xy history (default 10)")
        sp.add_argument("--horizon", type=FRAMES, default=30,
                        help="H, frames of predicted giver xyz (default 30)")
        sp.add_argument("--val-fraction", type=fraction, default=0.1,
                        help="fraction of training episodes held out for validation (default 0.1)")
        sp.add_argument(
            "--folds",
            type=FOLDS,
            default=10,
            help="number of stratified folds for --test-fold",
        )
        sp.add_argument(
            "--test-fold",
            type=int_in_range(0, FOLDS.high - 1),
            default=None,
            help="hold out this fold entirely and report "
            "the open-loop RMS (mm) on it after training (default: train on all episodes)",
        )
        sp.add_argument("--no-progress", action="store_true", help="no tqdm bars")

    bc = sub.add_parser(
        "bc-mlp",
        help="BC-MLP: torch MLP, receiver history -> 30-frame giver chunk",
        description="Train BC-MLP with early stopping on a validation split.",
    )
    common(bc)
    bc.add_argument(
        "--epochs",
        type=EPOCHS,
        default=None,
        help="maximum epochs (default 50; 3 with --smoke)",
    )
    bc.add_argument(
        "--patience",
        type=EPOCHS,
        default=5,
        help="early-stopping patience in epochs (default 5)",
    )
    bc.add_argument("--hidden", type=WIDTH, nargs="+", default=None,
                    help="hidden widths (default 256 256 256; 64 64 with --smoke)")
    bc.add_argument(
        "--giver-state",
        action="store_true",
        help="also condition on the current giver/robot "
        "xyz; off by default (the receiver history alone, exactly what the planner sees: in the "
        "env the giver is the robot's own TCP, and a model trained with it copies it)",
    )
    bc.set_defaults(func=train_bc_mlp)

    act = sub.add_parser(
        "act",
        help="ACT: LeRobot's ACTPolicy, state-only, trained on a LeRobot export",
        description="Train LeRobot's ACTPolicy on a LeRobotDataset export of the data.",
    )
    common(act)
    act.add_argument("--steps", type=STEPS, default=None,
                     help="optimisation steps (default 8000; 20 with --smoke)")
    act.add_argument("--eval-every", type=STEPS, default=None,
                     help="steps between validation/checkpoints (default 1000; 10 with --smoke)")
    act.add_argument(
        "--paper-scale",
        action="store_true",
        help="ACT's default size (dim 512, 8 heads, "
        "ffn 3200, 4 enc layers, VAE 4 layers, latent 32) instead of the CPU default "
        "(dim 128, 4 heads, ffn 512, 2 enc / 1 dec layers, VAE 1 layer, latent 16)",
    )
    act.add_argument("--no-vae", action="store_true", help="train without ACT's CVAE objective")
    act.add_argument(
        "--giver-state",
        action="store_true",
        help="also give ACT observation.state (the "
        "current giver/robot xyz); off by default: the receiver history alone, as in evaluate.py",
    )
    act.add_argument(
        "--dim-model", type=WIDTH, default=None, help="override the transformer width"
    )
    act.add_argument(
        "--n-heads", type=int_in_range(1, 1024), default=None, help="override the attention heads"
    )
    act.add_argument(
        "--dim-feedforward",
        type=WIDTH,
        default=None,
        help="override the feed-forward width",
    )
    act.add_argument(
        "--n-encoder-layers", type=LAYERS, default=None, help="override the encoder depth"
    )
    act.add_argument(
        "--n-decoder-layers", type=LAYERS, default=None, help="override the decoder depth"
    )
    act.add_argument(
        "--export-root",
        default=None,
        help="LeRobot export folder (default OUT/lerobot_dataset; "
        "reused only if it holds exactly this training set, else rebuilt (the default folder) "
        "or refused without --overwrite)",
    )
    act.set_defaults(func=train_act)

    from handover_eval.cli import preference as pref

    sp = sub.add_parser(
        "preference",
        help="CoSpar tunes Θ = {K, B, t_f, f_r} from simulated participants "
        "who judge real handovers in the env",
        description=pref.PREFERENCE_HELP,
    )
    pref.add_preference_arguments(sp)
    sp.set_defaults(func=pref.run_preference_command, threads=1, device="cpu")
    sc = sub.add_parser(
        "preference-check",
        help="acceptance: CoSpar's Θ̂ against the optimum brute-forced "
        "over a small grid (episodes cached)",
        description=pref.CHECK_HELP,
    )
    pref.add_check_arguments(sc)
    sc.set_defaults(func=pref.run_check_command, threads=1, device="cpu")

    from handover_eval.cli import rl

    rl.add_rl_parser(sub, load_data)
    return p


def _check_device(name: str) -> None:
    """A torch device that exists here, or a ValueError naming it."""
    import torch

    try:
        device = torch.device(name)
    except (RuntimeError, ValueError) as exc:
        raise ValueError(f"--device {name!r}: not a torch device ({exc})") from None
    available = {
        "cpu": True,
        "cuda": torch.cuda.is_available(),
        "mps": getattr(torch.backends, "mps", None) is not None
        and torch.backends.mps.is_available(),
    }
    if not available.get(device.type, False):
        raise ValueError(f"--device {name!r}: not available on this machine")


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit status (2 for bad input, 130 when interrupted)."""
    hub_offline()
    args = build_parser().parse_args(argv)
    args.argv = ["train.py", *(sys.argv[1:] if argv is None else argv)]  # as typed (provenance)
    import torch

    torch.set_num_threads(max(1, args.threads))
    try:
        _check_device(args.device)
        args.func(args)
    except (ValueError, OSError, FloatingPointError) as exc:  # DatasetError, CheckpointError, ...
        print(f"train.py: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if args.method.startswith("preference"):
            print("train.py: interrupted", file=sys.stderr)
            return 130
        print(
            f"train.py: interrupted; the last checkpoint in {args.out} is intact (continue with "
            "--resume)",
            file=sys.stderr,
        )
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
