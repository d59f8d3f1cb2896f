"""Argument types, checks and flags shared by the command lines of :mod:`handover_eval.cli`
(``train.py``, ``evaluate.py``, ``handover-data``).

* :class:`IntRange` (made by :func:`int_in_range`) bounds every integer count flag (iterations,
  participants, walks, episodes, workers, seeds, epochs, steps, ...) by a stated minimum and
  maximum: as an argparse ``type`` it gives argparse's error naming the flag; :func:`check_counts`
  applies the same bounds after parsing for the commands whose bad values are one-line errors of
  the command itself (``evaluate.py``'s open- and closed-loop commands).
* :func:`positive_float`, :func:`fraction`, :func:`closed_fraction`, :func:`theta_grid`: the other
  numeric option types.
* :func:`add_backend_arguments`, :func:`backend_from_args`: ``--backend`` / ``--ray-address``.
* :data:`SEEDS`, :data:`WORKERS`, :data:`FOLDS`, ...: the bounds shared by several commands.

Output folders are checked by :func:`handover_env.paths.output_folder` (through
:func:`folder_option` where the option has a default folder: an empty ``--out ""`` is refused, never
taken for "unset") and locked by :class:`handover_eval.output_lock.OutputLock`.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Mapping
from pathlib import Path

from handover_env.paths import output_folder
from handover_env.sensors.profiles import PROFILES
from handover_eval.backend import BACKENDS, Backend, import_ray


class IntRange:
    """argparse type: a whole number in ``[low, high]``; the error states both bounds."""

    def __init__(self, low: int, high: int) -> None:
        if not low <= high:
            raise ValueError(f"empty range [{low}, {high}]")
        self.low, self.high = low, high
        self.__name__ = f"integer in [{low}, {high}]"

    def problem(self, value: int) -> str | None:
        """Why ``value`` is out of range (None if it is in range)."""
        if self.low <= value <= self.high:
            return None
        return f"must be an integer in [{self.low}, {self.high}], got {value}"

    def __call__(self, text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        problem = self.problem(value)
        if problem:
            raise argparse.ArgumentTypeError(problem)
        return value

    def check(self, flag: str, value: int | list[int] | None) -> None:
        """Raise ValueError naming ``flag`` unless ``value`` (or each of a list; None = unset) is
        in range."""
        for v in value if isinstance(value, (list, tuple)) else [value]:
            problem = None if v is None else self.problem(v)
            if problem:
                raise ValueError(f"{flag} {problem}")

    def __repr__(self) -> str:
        return f"int_in_range({self.low}, {self.high})"


def int_in_range(low: int, high: int) -> IntRange:
    """argparse type: an integer in ``[low, high]`` (e.g. ``int_in_range(1, 10_000)``)."""
    return IntRange(low, high)


#: Seeds: what numpy's and torch's generators both take.
SEEDS = int_in_range(0, 2**32 - 1)
#: Worker processes (one core each).
WORKERS = int_in_range(1, 256)
#: k of a stratified k-fold split.
FOLDS = int_in_range(2, 100)
#: Training budgets and frame counts (train.py, evaluate.py).
EPOCHS = int_in_range(1, 100_000)
STEPS = int_in_range(1, 10_000_000)
FRAMES = int_in_range(1, 10_000)
#: Simulated participants, CoSpar iterations, walks per proposed Θ (train.py preference and
#: preference-check, evaluate.py user-study).
PARTICIPANTS = int_in_range(1, 1000)
ITERATIONS = int_in_range(1, 10_000)
WALKS = int_in_range(1, 1000)


def check_counts(args: argparse.Namespace, counts: Mapping[str, IntRange]) -> None:
    """Apply ``counts`` (flag -> bounds) to the parsed ``args``; ValueError naming the first flag
    out of range. Flags a sub-command does not have are skipped."""
    for flag, bounds in counts.items():
        bounds.check(flag, getattr(args, flag.lstrip("-").replace("-", "_"), None))


def positive_float(text: str) -> float:
    """argparse type: a finite float > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a float, got {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a positive float, got {text}")
    return value


positive_float.__name__ = "positive float"


def fraction(text: str) -> float:
    """argparse type: a float in (0, 1)."""
    value = positive_float(text)
    if not value < 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {text}")
    return value


def closed_fraction(text: str) -> float:
    """argparse type: a float in [0, 1] (a share that may be none or all, e.g. of OOD episodes)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a float, got {text!r}") from None
    if not 0.0 <= value <= 1.0:  # NaN fails too
        raise argparse.ArgumentTypeError(f"must be in [0, 1], got {text}")
    return value


#: Grid points per Θ parameter of CoSpar (CoSparConfig also caps their product).
GRID_POINTS = int_in_range(2, 5000)


def theta_grid(text: str) -> tuple[int, int, int, int]:
    """argparse type: CoSpar's grid points per parameter, ``NK,NB,NT,NF`` (or ``NKxNBxNTxNF``)."""
    parts = text.replace("x", ",").split(",")
    try:
        values = tuple(int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 4 whole numbers like 7,6,6,7, got {text!r}"
        ) from None
    if len(values) != 4 or any(GRID_POINTS.problem(v) for v in values):
        raise argparse.ArgumentTypeError(
            f"expected 4 numbers in [{GRID_POINTS.low}, {GRID_POINTS.high}] (K, B, t_f, f_r), "
            f"got {text!r}"
        )
    return values  # type: ignore[return-value]


def add_sensing_argument(parser: argparse.ArgumentParser, default: str = "paper") -> None:
    """``--sensing``: the env's sensor profile (docs/sensing.md)."""
    parser.add_argument(
        "--sensing",
        choices=PROFILES,
        default=default,
        help="the env's sensor profile (docs/sensing.md): the paper's camera, wrist F/T and "
        f"controller; the exact world; or drawn per episode (default: {default})",
    )


def add_person_argument(parser: argparse.ArgumentParser) -> None:
    """``--person``: person switches set apart from their defaults (docs/simulator.md)."""
    from handover_env.person.settings import SWITCHES, ReceiverConfig, switch_tokens

    def token(value: str) -> str:
        try:
            switch_tokens([value])
        except ValueError as err:
            raise argparse.ArgumentTypeError(str(err)) from None
        return value

    defaults = ReceiverConfig()
    parser.add_argument(
        "--person",
        nargs="+",
        type=token,
        default=[],
        metavar="SWITCH",
        help="set person switches apart from their defaults, each as NAME (on), NAME=on or "
        f"NAME=off, NAME any of {list(SWITCHES)} (docs/simulator.md): reach_offset, the "
        "person's own reach offset (scripted walkers draw it with their seed, a replay carries "
        "its recorded one); arm_yield, a reaching arm that pushes at most as hard as a human "
        "arm and stops on contact with the robot; avoid_gripper, a held object drawn out of "
        "the gripper by its open side (defaults: "
        + ", ".join(f"{s} {'on' if getattr(defaults, s) else 'off'}" for s in SWITCHES)
        + "; none given: the default person)",
    )


def add_backend_arguments(parser: argparse.ArgumentParser) -> None:
    """``--backend process|ray`` and ``--ray-address`` (shared by every command that fans out)."""
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="process",
        help="where the jobs run: 'process' (spawned processes on this machine, the "
        "default) or 'ray' (Ray tasks of one CPU each; needs the [cluster] extra); "
        "the results do not depend on it",
    )
    parser.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDRESS",
        help="with --backend ray: the cluster to join ('auto' = the one `ray start` set "
        "up on this node, or host:port); default: start a local Ray instance with "
        "--workers CPUs for this command",
    )


def backend_from_args(args: argparse.Namespace) -> Backend:
    """The :class:`Backend` of parsed ``--backend`` / ``--ray-address``; ValueError or a clear
    RuntimeError (Ray missing) on bad input."""
    backend = Backend(getattr(args, "backend", "process"), getattr(args, "ray_address", None))
    if backend.kind == "ray":
        import_ray()
    return backend


def load_replay_data(load: Callable, path: str | None, quick: bool, seed: int,
                     progress: bool = True):
    """``--replay-data PATH`` loaded with the command's own dataset loader ``load(path, quick,
    seed, progress)``, or None without the flag; FileNotFoundError naming the flag for a missing
    path."""
    if path is None:
        return None
    if not Path(path).exists():
        raise FileNotFoundError(f"--replay-data {path}: no such file or folder")
    return load(path, quick, seed, progress)


def folder_option(value: str | None, flag: str, default: str | Path) -> Path:
    """The output folder given as option ``flag`` (its parsed ``value``), or ``default`` when the
    option was not given (None). Anything given is checked by
    :func:`handover_env.paths.output_folder`, so ``--out ""`` (an unset shell variable) is a
    one-line :class:`~handover_env.paths.UnsafePathError` naming ``flag``, never the default."""
    return output_folder(default if value is None else value, flag)
