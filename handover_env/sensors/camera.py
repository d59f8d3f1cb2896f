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
a keypoint with zero noise and a camera that never loses the body draw nothing. A frame is one
compiled call (:func:`handover_env.sensors.camera_frame.camera_frame`) on the camera's state
array: :meth:`Camera.frame` checks its input and calls it, :meth:`Camera.capture` is the same call
without the checks for the env's 30 Hz step. No smoothing is added: the ZED SDK documentation says
its tracking filters detections but not how, and the noise figures are measured on its output.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from handover_env.sensors import camera_frame as cf
from handover_env.sensors.profiles import CameraParams

#: Keypoints the camera model knows, with their noise fields and dimensions (2: xy, 3: xyz).
KEYPOINTS: dict[str, str] = {"pelvis": "pelvis", "hand": "hand"}
_ORDER = ("hand", "pelvis")  # the kernel's keypoints, in the order they are drawn
_NONE = np.empty(0)  # a keypoint not given


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
        #: the compiled frame's state (:mod:`handover_env.sensors.camera_frame`), set by reset
        self.state = np.empty(0)

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
        delay = self.delay_frames
        cs = self.state = np.zeros(cf.size(delay))
        cs[cf.T_LAST] = -math.inf
        cs[cf.DELAY] = delay
        cs[cf.STAY] = 1.0 - 1.0 / p.lost_run  # P(lost -> lost)
        cs[cf.START] = (min(1.0, p.lost_fraction / (p.lost_run * (1.0 - p.lost_fraction)))
                        if p.lost_fraction > 0 else 0.0)
        for k, name in enumerate(_ORDER):  # sigma 0: no noise and no draws
            field = KEYPOINTS[name]
            sigma, rho = getattr(p, f"{field}_sigma"), getattr(p, f"{field}_rho")
            cs[cf.PAR + 3 * k:cf.PAR + 3 * k + 3] = sigma, rho, math.sqrt(1.0 - rho**2) * sigma
        return self

    def _draw(self, need: int) -> None:
        """Refill the pool the kernel asked for (:data:`~handover_env.sensors.camera_frame.
        NEED_NORMALS` or ``NEED_UNIFORMS``) from the episode's Generator."""
        cs, rng, z = self.state, self._rng, cf.Z
        if need == cf.NEED_NORMALS:  # the normals left, then a new block
            i, n = int(cs[cf.ZI]), int(cs[cf.ZN])
            left = n - i
            cs[z:z + left] = cs[z + i:z + n].copy()
            cs[z + left:z + left + cf.BLOCK] = rng.standard_normal(cf.BLOCK)  # type: ignore[union-attr]
            cs[cf.ZI], cs[cf.ZN] = 0, left + cf.BLOCK
        else:
            cs[cf.U:cf.U + cf.BLOCK] = rng.random(cf.BLOCK)  # type: ignore[union-attr]
            cs[cf.UI], cs[cf.UN] = 0, cf.BLOCK

    def capture(self, t: float, hand: np.ndarray, pelvis: np.ndarray) -> list[float]:
        """:meth:`frame` without its checks, for the env's hot path: ``hand`` and ``pelvis`` are
        contiguous float64 arrays (3 and 2 or 3 numbers; an empty array: not given), ``t`` a
        float not before the last call's. Returns the delivered frame's ``[hand (3), pelvis
        (3)]`` (a 2-D pelvis fills the first two); its time and tracking state are in
        :attr:`state` (``OUT``).
        """
        cs = self.state
        need = cf.camera_frame(cs, t, hand, pelvis)
        while need != cf.DONE:
            self._draw(need)
            need = cf.camera_frame(cs, t, hand, pelvis)
        return cs[cf.OUT + cf.R_PTS:cf.OUT + cf.R_PTS + 6].tolist()

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
        t_last = float(self.state[cf.T_LAST])
        if t < t_last:
            raise ValueError(f"t must not go back: {t} after {t_last}")
        if not isinstance(true_points, Mapping):
            raise ValueError(f"true_points must be a dict, got {type(true_points).__name__}")
        given = {name: _NONE for name in _ORDER}
        for name in sorted(true_points):
            if name not in KEYPOINTS:
                raise ValueError(f"unknown keypoint {name!r}; known: {sorted(KEYPOINTS)}")
            x = np.asarray(true_points[name], dtype=np.float64)
            if x.ndim != 1 or x.shape[0] not in (2, 3) or not np.isfinite(x).all():
                raise ValueError(f"keypoint {name!r} must be 2 or 3 finite numbers, got {x!r}")
            given[name] = np.ascontiguousarray(x)
        self.capture(float(t), given["hand"], given["pelvis"])
        cs, out = self.state, cf.OUT
        points = {}
        for k, name in enumerate(_ORDER):
            dim = int(cs[out + cf.R_DIM + k])
            if dim:
                p = out + cf.R_PTS + 3 * k
                points[name] = cs[p:p + dim].copy()
        return Observation(points, bool(cs[out + cf.R_TRACKED]), float(cs[out + cf.R_T]))
