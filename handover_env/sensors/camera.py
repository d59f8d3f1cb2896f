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

Every random number comes from the Generator given to :meth:`Camera.reset`, in capture order
(normals and uniforms each drawn in blocks of 256), so an episode is reproducible from its seed;
a keypoint with zero noise and a camera that never loses the body draw nothing. :meth:`Camera.frame`
checks its input; :meth:`Camera.frame_fast` is the same model on plain floats for the env's
30 Hz step. No smoothing is added: the ZED SDK documentation says
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
_ENV_NAMES = ("hand", "pelvis")  # sorted, as frame() orders the keypoints
_BLOCK = 256  # random numbers drawn from the Generator at a time (same stream, fewer calls)


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
        p = self.params
        self._rng = rng
        # (sigma, rho, sqrt(1 - rho^2) sigma) per keypoint; sigma 0: no noise and no draws
        self._noise_par = {
            name: (getattr(p, f"{k}_sigma"), getattr(p, f"{k}_rho"),
                   math.sqrt(1.0 - getattr(p, f"{k}_rho") ** 2) * getattr(p, f"{k}_sigma"))
            for name, k in KEYPOINTS.items()
        }
        self._noise: dict[str, list[float]] = {}
        self._z: list[float] = []  # standard normals drawn in blocks from rng, used in order
        self._zi = 0
        self._u: list[float] = []  # uniforms for the loss chain, likewise
        self._ui = 0
        self._lost = False
        self._stay = 1.0 - 1.0 / p.lost_run  # P(lost -> lost)
        self._start = (min(1.0, p.lost_fraction / (p.lost_run * (1.0 - p.lost_fraction)))
                       if p.lost_fraction > 0 else 0.0)
        self._delay = self.delay_frames
        self._frames: deque[tuple[float, tuple[str, ...], list[list[float]], bool]] = deque(
            maxlen=self._delay + 1
        )
        self._last_tracked: tuple[float, tuple[str, ...], list[list[float]]] | None = None
        self._t_last = -math.inf
        return self

    def _normal(self) -> float:
        i = self._zi
        if i >= len(self._z):
            self._z = self._rng.standard_normal(_BLOCK).tolist()  # type: ignore[union-attr]
            i = 0
        self._zi = i + 1
        return self._z[i]

    def _draw_lost(self) -> bool:
        if self._start <= 0.0:
            return False
        i = self._ui
        if i >= len(self._u):
            self._u = self._rng.random(_BLOCK).tolist()  # type: ignore[union-attr]
            i = 0
        self._ui = i + 1
        self._lost = self._u[i] < (self._stay if self._lost else self._start)
        return self._lost

    def _capture(self, t: float, names: tuple[str, ...],
                 values: list[list[float]]
                 ) -> tuple[tuple[str, ...], list[list[float]], bool, float]:
        """The core of :meth:`frame` on plain floats (no checks): the delivered frame's
        (keypoint names, points, tracked, t_capture).

        The returned lists belong to the camera: copy them to keep them past the next call.
        """
        captured = []
        for name, x in zip(names, values):
            sigma, rho, c = self._noise_par[name]
            if sigma > 0.0:
                prev = self._noise.get(name)
                if prev is None or len(prev) != len(x):
                    n = [sigma * self._normal() for _ in x]
                else:
                    n = [rho * q + c * self._normal() for q in prev]
                self._noise[name] = n
                x = [a + b for a, b in zip(x, n)]
            captured.append(x)
        lost = self._draw_lost()
        frames = self._frames
        frames.append((t, names, captured, not lost))
        t_cap, f_names, points, tracked = frames[0]
        if len(frames) <= self._delay:  # nothing delivered yet
            return f_names, points, False, t_cap
        if tracked:
            self._last_tracked = (t_cap, f_names, points)
            return f_names, points, True, t_cap
        held = self._last_tracked
        if held is None:
            return f_names, points, False, t_cap
        return held[1], held[2], False, held[0]

    def frame_fast(self, t: float, pelvis: list[float],
                   hand: list[float]) -> tuple[list[list[float]], bool, float]:
        """:meth:`frame` for the env's hot path: plain floats in, ``([pelvis, hand], tracked,
        t_capture)`` out, no checks (the env's times and positions are valid by construction).

        Same random draws, in the same order, as ``frame(t, {"hand": ..., "pelvis": ...})``.
        The returned lists belong to the camera (read them before the next call).
        """
        self._t_last = t
        _, points, tracked, t_cap = self._capture(t, _ENV_NAMES, [hand, pelvis])
        return [points[1], points[0]], tracked, t_cap

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
        names = tuple(sorted(true_points))
        values = []
        for name in names:
            if name not in KEYPOINTS:
                raise ValueError(f"unknown keypoint {name!r}; known: {sorted(KEYPOINTS)}")
            x = np.asarray(true_points[name], dtype=np.float64)
            if x.ndim != 1 or x.shape[0] not in (2, 3) or not np.isfinite(x).all():
                raise ValueError(f"keypoint {name!r} must be 2 or 3 finite numbers, got {x!r}")
            values.append(x.tolist())
        self._t_last = float(t)
        f_names, points, tracked, t_cap = self._capture(float(t), names, values)
        return Observation({k: np.array(v) for k, v in zip(f_names, points)}, tracked, t_cap)
