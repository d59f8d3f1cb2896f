"""A small learnable handover-like dataset built from arrays, for the baseline tests (no real
data)."""

from __future__ import annotations

import numpy as np

from handover_env.data.dataset import Episode, HandoverDataset


def toy_dataset(n: int = 24, length: int = 60, seed: int = 0) -> HandoverDataset:
    """``n`` straight walks toward -x; the giver wrist is a smooth function of the receiver
    position."""
    rng = np.random.default_rng(seed)
    episodes = []
    for i in range(n):
        T = length + int(rng.integers(0, 20))
        t = np.arange(T) / 30.0
        start = np.array([2.0 + rng.normal(0, 0.3), -0.8 + rng.normal(0, 0.2)])
        velocity = np.array([-0.8 + rng.normal(0, 0.1), rng.normal(0, 0.05)])
        receiver = start + t[:, None] * velocity
        giver = np.stack(
            [
                0.3 + 0.2 * np.tanh(receiver[:, 0]),
                0.5 * receiver[:, 1],
                1.0 + 0.2 * np.exp(-(receiver[:, 0] ** 2)),
            ],
            axis=1,
        )
        hand = np.c_[receiver, np.full(T, 1.0)]
        quat = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
        episodes.append(
            Episode(receiver, hand, giver, quat, is_ood=(i % 6 == 5), source_id=f"toy_{i:03d}")
        )
    return HandoverDataset(episodes, name=f"toy(seed={seed})")
