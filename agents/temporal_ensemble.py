"""Temporal ensembling of overlapping action chunks (ACT, Zhao et al. 2023; paper Sec. IV-C).

Every 30 Hz frame the planner predicts a chunk of H future giver positions; chunk c, predicted
at frame s_c, gives row ``f - s_c`` as its estimate of the target at frame f (for
0 <= f - s_c < H). The ensembled target at frame f is the weighted mean of the estimates of
every stored chunk that covers f::

    target(f) = sum_i w_i * chunk_i[f - s_i] / sum_i w_i,     w_i = exp(-m * i)

**Direction (as in ACT):** i = 0 is the *oldest* chunk that still covers f, i = 1 the next
older one, ..., the newest chunk has the largest i. With ACT's default m = 0.01 the oldest
estimate weighs most, and only slightly (weights 1, 0.99, ...): the ensemble smooths. m = 0
is the plain mean; m < 0 favours the newest chunk (more reactive, less smooth).

Fractional frames (the forecast time t_f is not a multiple of 1/30 s) are linearly
interpolated between the ensembled targets at the two neighbouring frames.
"""

from __future__ import annotations

import math

import numpy as np


class TemporalEnsembler:
    """A ring buffer of the last H chunks and their start frames.

    Args:
        horizon: H, rows per chunk (= the number of chunks that can overlap one frame).
        m: exponential weight rate (see module docstring for the direction).
        dim: width of one row (3 for xyz).
    """

    def __init__(self, horizon: int = 30, m: float = 0.01, dim: int = 3) -> None:
        if not isinstance(horizon, (int, np.integer)) or horizon < 1:
            raise ValueError(f"horizon must be an integer >= 1, got {horizon!r}")
        if not math.isfinite(float(m)):
            raise ValueError(f"m must be finite, got {m!r}")
        self.horizon = int(horizon)
        self.m = float(m)
        self.dim = int(dim)
        self.reset()

    def reset(self) -> None:
        """Drop every stored chunk."""
        self._chunks = np.zeros((self.horizon, self.horizon, self.dim))
        self._starts = np.full(self.horizon, np.iinfo(np.int64).min // 2, dtype=np.int64)
        self._count = 0
        self.latest_start: int | None = None

    @property
    def empty(self) -> bool:
        return self._count == 0

    def add(self, chunk: np.ndarray, start_frame: int) -> None:
        """Store a chunk whose row 0 is the estimate for ``start_frame``.

        Start frames must not decrease; a chunk for the same start frame replaces the earlier one.
        """
        chunk = np.asarray(chunk, dtype=np.float64)
        if chunk.shape != (self.horizon, self.dim):
            raise ValueError(
                f"chunk must have shape ({self.horizon}, {self.dim}), got {chunk.shape}"
            )
        if not np.all(np.isfinite(chunk)):
            raise ValueError("chunk contains NaN or inf")
        start_frame = int(start_frame)
        if self.latest_start is not None and start_frame < self.latest_start:
            raise ValueError(
                f"start frames must not decrease: {start_frame} after {self.latest_start}"
            )
        slot = start_frame % self.horizon
        self._chunks[slot] = chunk
        self._starts[slot] = start_frame
        self._count = min(self._count + 1, self.horizon)
        self.latest_start = start_frame

    def at_frame(self, frame: int) -> np.ndarray | None:
        """Ensembled estimate (dim,) for an integer frame, or None when no chunk covers it."""
        offset = frame - self._starts  # (H,)
        valid = (offset >= 0) & (offset < self.horizon)
        if not valid.any():
            return None
        slots = np.flatnonzero(valid)
        slots = slots[np.argsort(self._starts[slots])]  # oldest first: i = 0, 1, ...
        w = np.exp(-self.m * np.arange(slots.size))
        rows = self._chunks[slots, offset[slots]]
        return (w @ rows) / w.sum()

    def at(self, frame: float) -> np.ndarray | None:
        """Ensembled estimate at a fractional frame (linear interpolation between frames).

        Frames past the newest chunk's last row use the last covered frame (hold).
        """
        if self.latest_start is None:
            return None
        last = self.latest_start + self.horizon - 1
        frame = min(float(frame), float(last))
        lo = math.floor(frame)
        frac = frame - lo
        a = self.at_frame(lo)
        if a is None:  # before the oldest stored chunk: use the newest chunk's first row
            return self.at_frame(self.latest_start)
        if frac <= 1e-12:
            return a
        b = self.at_frame(lo + 1)
        return a if b is None else (1.0 - frac) * a + frac * b
