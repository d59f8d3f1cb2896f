"""The ZED 2i body tracker seen by the agent: latency, keypoint noise and lost frames.

Call :meth:`Camera.reset` at an episode's start, then :meth:`Camera.frame` once per camera frame
(each 30 Hz env step) with the true keypoints at that instant; it returns what the agent sees now:

* **Latency.** A frame captured at ``t_c`` becomes available at ``t_c + latency`` (exposure,
  USB transport, inference and body fitting; :data:`~handover_env.sensors.profiles.CAMERA_FIELDS`).
  ``frame(t, ...)`` returns the newest frame available at ``t``; frames are captured at the call
  times, so the delay is ``ceil(latency * rate_hz)`` frames. Before the first frame is available
  the earliest capture is returned, flagged ``tracked=False``.
* **Noise.** Each keypoint's error is a first-order Gauss-Markov (AR(1)) process per axis,
  ``n_k = rho n_{k-1} + sqrt(1 - rho^2) sigma w_k``, drawn at capture (stationary from the first
  frame), independently per keypoint (``"pelvis"``, ``"hand"``).
* **Lost frames.** Body trackers report a tracking state (ZED SDK: ``OBJECT_TRACKING_STATE``
  OK / SEARCHING). Losses follow a two-state Markov chain per captured frame with long-run
  fraction ``lost_fraction`` and geometric runs of mean ``lost_run`` frames. A lost frame delivers
  the last tracked observation again (points and ``t_capture`` held) with ``tracked=False``.

Every random number comes from the Generator given to :meth:`Camera.reset`, in capture order, so
an episode is reproducible from its seed. No smoothing is added: the ZED SDK documentation says
its tracking filters detections but not how, and the noise figures are measured on its output.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from handover_env.sensors.profiles import CameraParams

#: Keypoints the camera model knows, with their noise fields and dimensions (2: xy, 3: xyz).
KEYPOINTS: dict[str, str] = {"pelvis": "pelvis", "hand": "hand"}


@dataclass(frozen=True)
class Observation:
    """What the agent sees at one frame.

    Attributes:
        points: keypoint name -> observed position (a new array of the true point's shape).
        tracked: False when the tracker had lost the body (or no frame is available yet).
        t_capture: when the delivered frame was captured, s.
    """

    points: dict[str, np.ndarray]
    tracked: bool
    t_capture: float


class Camera:
    """Body tracking at ``params.rate_hz`` with latency, AR(1) keypoint noise and lost frames."""

    def __init__(self, params: CameraParams | None = None) -> None:
        if params is not None and not isinstance(params, CameraParams):
            raise ValueError(f"params must be CameraParams, got {type(params).__name__}")
        self.params = params or CameraParams()
        self._rng: np.random.Generator | None = None

    @property
    def delay_frames(self) -> int:
        """Frames between capture and availability: ceil(latency x rate), 1e-9 tolerant."""
        p = self.params
        return max(0, math.ceil(p.latency * p.rate_hz - 1e-9))

    def reset(self, rng: np.random.Generator) -> Camera:
        """Start an episode; all randomness of the episode comes from ``rng``. Returns self."""
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        self._rng = rng
        self._noise: dict[str, np.ndarray] = {}
        self._lost = False
        self._frames: deque[tuple[float, dict[str, np.ndarray], bool]] = deque(
            maxlen=self.delay_frames + 1
        )
        self._last_tracked: Observation | None = None
        self._t_last = -math.inf
        return self

    def _draw_noise(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        p, rng = self.params, self._rng
        sigma = getattr(p, f"{KEYPOINTS[name]}_sigma")
        rho = getattr(p, f"{KEYPOINTS[name]}_rho")
        w = rng.standard_normal(shape)  # type: ignore[union-attr]
        prev = self._noise.get(name)
        n = sigma * w if prev is None else rho * prev + math.sqrt(1.0 - rho * rho) * sigma * w
        self._noise[name] = n
        return n

    def _draw_lost(self) -> bool:
        p = self.params
        if p.lost_fraction <= 0.0:
            return False
        u = float(self._rng.random())  # type: ignore[union-attr]
        stay = 1.0 - 1.0 / p.lost_run  # P(lost -> lost)
        start = min(1.0, p.lost_fraction / (p.lost_run * (1.0 - p.lost_fraction)))
        self._lost = u < (stay if self._lost else start)
        return self._lost

    def frame(self, t: float, true_points: Mapping[str, np.ndarray]) -> Observation:
        """Capture the true keypoints at ``t`` and return the observation available at ``t``.

        Args:
            t: time, s, non-decreasing between calls of an episode.
            true_points: ``{"pelvis": (2,) or (3,), "hand": (3,)}`` (any subset), metres.

        Raises:
            RuntimeError: called before :meth:`reset`.
            ValueError: a bad time, an unknown keypoint, or a non-finite position.
        """
        if self._rng is None:
            raise RuntimeError("Camera.frame() called before reset(rng)")
        if not (isinstance(t, (int, float, np.floating, np.integer)) and math.isfinite(t)):
            raise ValueError(f"t must be a finite number of seconds, got {t!r}")
        if t < self._t_last:
            raise ValueError(f"t must not go back: {t} after {self._t_last}")
        if not isinstance(true_points, Mapping):
            raise ValueError(f"true_points must be a dict, got {type(true_points).__name__}")
        self._t_last = float(t)
        captured = {}
        for name in sorted(true_points):
            if name not in KEYPOINTS:
                raise ValueError(f"unknown keypoint {name!r}; known: {sorted(KEYPOINTS)}")
            x = np.asarray(true_points[name], dtype=np.float64)
            if x.ndim != 1 or x.shape[0] not in (2, 3) or not np.isfinite(x).all():
                raise ValueError(f"keypoint {name!r} must be 2 or 3 finite numbers, got {x!r}")
            captured[name] = x + self._draw_noise(name, x.shape)
        lost = self._draw_lost()
        self._frames.append((float(t), captured, not lost))
        t_cap, points, tracked = self._frames[0]
        if len(self._frames) <= self.delay_frames:  # nothing delivered yet
            return Observation({k: v.copy() for k, v in points.items()}, False, t_cap)
        if tracked:
            obs = Observation({k: v.copy() for k, v in points.items()}, True, t_cap)
            self._last_tracked = obs
            return obs
        held = self._last_tracked
        if held is None:
            return Observation({k: v.copy() for k, v in points.items()}, False, t_cap)
        return Observation({k: v.copy() for k, v in held.points.items()}, False, held.t_capture)
