"""Pink (1/f) action noise for SAC, as an SB3 ``ActionNoise``.

Coloured noise of exponent β has a power spectral density ∝ 1/f^β: β = 0 is white noise, β = 2
a random walk, β = 1 pink noise, between the two; Eberhard et al. ("Pink Noise Is All You Need:
Colored Noise Exploration in Deep Reinforcement Learning", ICLR 2023) found pink noise the best
default for off-policy exploration of continuous control. A sequence of ``length`` steps per
action dimension is drawn at once by shaping white Gaussian noise in the frequency domain
(Timmer and König 1995: each Fourier coefficient scaled by f^(-β/2), the zero frequency removed),
normalised to unit standard deviation and scaled by ``sigma``; a new sequence is drawn when one
is used up and at every episode's reset.

SB3's SAC adds an ``ActionNoise`` to its sampled action (its squashed Gaussian; the sum is
clipped to [-1, 1]); it does not replace SAC's own sampling with it, as the authors' package
does by a custom action distribution. Here the noise is added, with SB3 alone. Each env of the
vector env has its own generator, seeded from (run seed, env index), so a run's noise is the
same for the same seed.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.noise import ActionNoise, VectorizedActionNoise

#: Steps of one drawn sequence (an episode is at most 450 steps; 15 s at 30 Hz).
SEQUENCE = 512


def coloured_noise(beta: float, size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(dims, steps) Gaussian noise with a 1/f^beta spectrum along the steps, unit standard
    deviation per dimension (Timmer and König 1995)."""
    dims, steps = size
    freqs = np.fft.rfftfreq(steps)
    scale = np.zeros_like(freqs)
    scale[1:] = freqs[1:] ** (-beta / 2.0)
    coeffs = scale * (rng.standard_normal((dims, freqs.size))
                      + 1j * rng.standard_normal((dims, freqs.size)))
    if steps % 2 == 0:  # the Nyquist coefficient of a real signal is real
        coeffs[:, -1] = coeffs[:, -1].real * np.sqrt(2.0)
    x = np.fft.irfft(coeffs, n=steps, axis=-1)
    return x / x.std(axis=-1, keepdims=True)


class ColouredActionNoise(ActionNoise):
    """1/f^beta noise of standard deviation ``sigma`` per action dimension (module docstring).

    Args:
        beta: the spectral exponent (1: pink).
        sigma: standard deviation, in action units ([-1, 1]).
        dims: action dimensions.
        seed: the generator's seed (a sequence of ints, as numpy's ``default_rng`` takes).
        length: steps of one drawn sequence.
    """

    def __init__(self, beta: float, sigma: float, dims: int, seed: list[int],
                 length: int = SEQUENCE) -> None:
        super().__init__()
        self.beta, self.sigma, self.dims, self.length = beta, sigma, dims, length
        self.rng = np.random.default_rng(seed)
        self._draw()

    def _draw(self) -> None:
        self._seq = self.sigma * coloured_noise(self.beta, (self.dims, self.length), self.rng)
        self._i = 0

    def __call__(self) -> np.ndarray:
        if self._i >= self.length:
            self._draw()
        out = self._seq[:, self._i].astype(np.float32)
        self._i += 1
        return out

    def reset(self) -> None:
        self._draw()


def pink_noise(sigma: float, dims: int, n_envs: int, seed: int) -> VectorizedActionNoise:
    """SAC's ``action_noise``: pink noise for each of ``n_envs`` envs, seeded from (``seed``,
    env index)."""
    noise = VectorizedActionNoise(ColouredActionNoise(1.0, sigma, dims, [seed, 0]), n_envs)
    noise.noises = [ColouredActionNoise(1.0, sigma, dims, [seed, 0x91, i])
                    for i in range(n_envs)]
    return noise
