"""Dropout masks for CPU training of ACT: drawn from numpy's SFC64, re-seeded every step.

:func:`fast_dropout` swaps the ``nn.Dropout`` modules of a policy for :class:`FastDropout`, whose
masks come from :class:`DropoutMasks`: the same i.i.d. Bernoulli(1 - p) keep-mask and 1/(1-p)
scaling as PyTorch's dropout, drawn from a generator seeded by ``(seed, step)``, so training stays
deterministic and resumable without extra state.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from handover_env.extras import missing_extra

try:
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None


class DropoutMasks:
    """Bernoulli keep-masks for dropout, drawn from numpy's SFC64 and re-seeded every step.

    ``torch.nn.Dropout`` on CPU draws its mask with ``bernoulli_`` (one mt19937 draw per element).
    This draws the same i.i.d. Bernoulli(1 - p) mask (keep if a uniform 32-bit word
    >= round(p 2^32), i.e. p exact to 2^-32) from SFC64's raw output, two 32-bit words per
    64-bit draw. Seeding from ``(seed, step)`` keeps training deterministic and resumable without
    extra state.
    """

    def __init__(self, seed: int) -> None:
        self.seed = int(seed) % 2**63
        self.reseed(0)

    def reseed(self, step: int) -> None:
        self._bits = np.random.SFC64(np.random.SeedSequence([self.seed, int(step)]))

    def noise(self, shape: torch.Size, p: float, dtype: torch.dtype) -> torch.Tensor:
        """Keep-mask scaled by 1/(1-p) (what ATen's dropout multiplies the input by)."""
        n = math.prod(shape)
        words = self._bits.random_raw((n + 1) // 2).view(np.uint32)[:n]
        threshold = np.uint32(min(round(p * 2.0**32), 2**32 - 1))
        np_dtype = np.float64 if dtype == torch.float64 else np.float32
        noise = np.multiply(words >= threshold, np_dtype(1.0 / (1.0 - p)), dtype=np_dtype)
        return torch.from_numpy(noise).view(shape).to(dtype)


class FastDropout(torch.nn.Dropout):
    """``nn.Dropout`` (same p, same train/eval behaviour) with its mask from
    :class:`DropoutMasks`."""

    def __init__(self, p: float, masks: DropoutMasks) -> None:
        super().__init__(p)
        self.masks = masks

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training or self.p == 0.0:
            return x
        return x * self.masks.noise(x.shape, self.p, x.dtype)


@contextlib.contextmanager
def fast_dropout(policy: torch.nn.Module, masks: DropoutMasks):
    """Swap every ``nn.Dropout`` module of ``policy`` for a :class:`FastDropout` while training.

    Only the dropout *modules* are swapped (the residual and feed-forward dropouts, ~87% of the
    dropped elements); ``nn.MultiheadAttention``'s internal attention dropout stays PyTorch's.
    The originals are put back on exit; dropout modules hold no weights, so checkpoints are
    unchanged.
    """
    swapped = []
    for parent in list(policy.modules()):
        for name, child in list(parent.named_children()):
            if type(child) is torch.nn.Dropout:
                setattr(parent, name, FastDropout(child.p, masks))
                swapped.append((parent, name, child))
    try:
        yield swapped
    finally:
        for parent, name, child in swapped:
            setattr(parent, name, child)
