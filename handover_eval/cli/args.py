"""Argument types and flags shared by the command lines of :mod:`handover_eval.cli`."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from handover_eval.backend import BACKENDS, Backend, import_ray


def int_at_least(low: int) -> Callable[[str], int]:
    """An argparse ``type``: a whole number >= ``low``, else a one-line usage error."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {value}")
        return value
    parse.__name__ = f"integer >= {low}"
    return parse


def grid_points(text: str) -> tuple[int, int, int, int]:
    """An argparse ``type``: CoSpar grid points per Θ parameter, ``NK,NB,NT,NF`` (each >= 2)."""
    parts = text.replace("x", ",").split(",")
    try:
        values = tuple(int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 4 whole numbers like 7,6,6,7, got {text!r}"
        ) from None
    if len(values) != 4 or min(values) < 2:
        raise argparse.ArgumentTypeError(f"expected 4 numbers >= 2 (K, B, t_f, f_r), got {text!r}")
    return values  # type: ignore[return-value]


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
