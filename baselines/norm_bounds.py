"""Bounds on the normalisation statistics a BC-MLP or ACT checkpoint may carry.

The statistics standardise the inputs and un-standardise the predicted chunk, so a crafted one
(``out_std = 1e30``) turns any prediction into a number of the same size. They are bounded by what
the data can produce: every position of an episode is within ``±MAX_ABS_COORD_M`` (100 m,
:mod:`handover_env.data.limits`, checked when an episode is built), so

* giver xyz (``observation.state``, ``action``) and the receiver's current xy (entries 0-1 of the
  environment state, :func:`handover_env.data.features.encode_receiver`) lie within ±L, and the
  history's offsets ``p_{t-k} - p_t`` (entries 2..2W-1) within ±2L;
* a mean, minimum, maximum or quantile of values within ±b lies within ±b, and their standard
  deviation within [0, b] (half the range). A zero one divides by zero, so it must be positive
  (BC-MLP stores at least its floor :data:`MIN_STD`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from baselines.checkpoint_io import CheckpointError
from handover_env.data.features import ACTION, OBS_ENV_STATE, OBS_STATE, STATE_DIM
from handover_env.data.limits import MAX_ABS_COORD_M

#: The smallest standard deviation BC-MLP stores (``BCMLPNet.set_stats`` floors at it).
MIN_STD = 1e-6
#: The statistics bounded like the values themselves (LeRobot's ``get_feature_stats`` names).
LOCATION_STATS = frozenset({"mean", "min", "max", "q01", "q10", "q50", "q90", "q99"})


def feature_limits(env_dim: int) -> dict[str, np.ndarray]:
    """Largest absolute value of each entry of the baseline features (see the module docstring)."""
    env = np.full(env_dim, 2.0 * MAX_ABS_COORD_M)
    env[:2] = MAX_ABS_COORD_M
    giver = np.full(STATE_DIM, MAX_ABS_COORD_M)
    return {OBS_ENV_STATE: env, OBS_STATE: giver, ACTION: giver.copy()}


def check_stat(
    source: Path, key: str, values, stat: str, limit: np.ndarray, min_std: float = 0.0
) -> None:
    """One normalisation statistic ``stat`` (``"mean"``, ``"std"``, ``"count"``, ...) within what
    the data can produce: ``|value| <= limit`` (``std`` in ``(0, limit]``, and ``>= min_std`` when
    given; ``count >= 0``).

    Args:
        source: the file, key: the tensor's name in it, for the message.
        values: the statistic (a tensor or array of ``limit``'s shape; ``count`` any).
        limit: the feature's bound per entry (:func:`feature_limits`).
        min_std: the smallest standard deviation the writer stores.

    Raises:
        CheckpointError: naming the file, the key, the first entry out of bounds and the bound.
    """
    v = np.asarray(values.detach().cpu().double() if hasattr(values, "detach") else values,
                   dtype=np.float64).reshape(-1)
    lo = float(np.float32(min_std))
    if stat == "count":
        bad = ~(v >= 0)
    elif stat == "std":
        bad = ~((v >= lo) & (v > 0) & (v <= limit))
    elif stat in LOCATION_STATS:
        bad = ~(np.abs(v) <= limit)
    else:
        raise CheckpointError(f"{source}: unexpected statistic {key!r}")
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        b = float(np.broadcast_to(limit, v.shape)[i]) if stat != "count" else 0.0
        what = {"count": ">= 0", "std": f"in ({lo:g}, {b:g}] m" if lo == 0 else
                f"in [{lo:g}, {b:g}] m"}.get(stat, f"within ±{b:g} m")
        raise CheckpointError(
            f"{source}: {key}[{i}] = {v[i]:.6g} is not {what}, what the data can produce "
            f"(positions within ±{MAX_ABS_COORD_M:g} m, history offsets ±{2 * MAX_ABS_COORD_M:g} m)"
        )
