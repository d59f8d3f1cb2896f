"""The UR5e's built-in wrist force/torque sensor as the release sees it (force part).

The env today gives the exact external force at the wrist (its payload compensation uses the
true mass and centre of mass, see :mod:`handover_env.envs.base_handover`). A real UR5e reports
the sensor reading less the *configured* payload, with the sensor's own errors. Per 200 Hz tick,
:meth:`WristFT.measure` turns the exact external force into that report:

1. **Payload compensation with the configured payload.** The configured mass and centre of mass
   differ from the true ones by errors drawn once per episode (sigma ``mass_error``, ``com_error``):
   the reading gains ``Δm (a - g)`` (``a - g``: the payload's specific force, what an
   accelerometer at the wrist reads, world frame) and, when the gripper's angular velocity and
   acceleration are given, ``Δ[m (α × c + ω × (ω × c))]``. A moving, imperfectly compensated
   payload therefore produces spurious forces; at rest only ``Δm g`` remains, which zeroing removes.
2. **Sensor errors, in the sensor frame.** An offset (3 sigma = datasheet ``accuracy``, drawn per
   episode), a random-walk drift (``drift`` N/sqrt(s)) and white noise.
3. **Zeroing.** :meth:`zero` is URScript's ``zero_ftsensor()``: it tares the current reading, in the
   sensor frame, so later readings are relative to it (the noise-free reading: see :meth:`zero`).
   The env calls it where a UR program would: once the grasp has settled at the ready pose,
   before the robot moves toward the person (docs/sensing.md). A rotation of the wrist after
   zeroing shows up as ``Δm g`` turning.
4. **Filter.** A first-order low-pass (``filter_tau``) in the world frame, as the env's own. The
   white noise is scaled so that the *filtered* reading's per-axis standard deviation is
   ``precision / 3`` (the datasheet's precision read as 3 sigma).

Deterministic given the Generator passed to :meth:`reset`; the "ideal" profile (no errors, no
zeroing) returns the env's filtered force exactly and draws no random numbers.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.sensors.profiles import WristFTParams


def _vec3(x: object, name: str) -> np.ndarray:
    v = np.asarray(x, dtype=np.float64)
    if v.shape != (3,) or not np.isfinite(v).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {x!r}")
    return v


def _rotation(r: object) -> np.ndarray:
    m = np.asarray(r, dtype=np.float64)
    if m.size == 9:
        m = m.reshape(3, 3)
    if m.shape != (3, 3) or not np.isfinite(m).all():
        raise ValueError(f"gripper_rotation must be a 3x3 rotation (or 9 numbers), got {r!r}")
    return m


class WristFT:
    """Force estimate of the UR5e wrist sensor with an imperfect payload (see module docstring)."""

    def __init__(self, params: WristFTParams | None = None) -> None:
        if params is not None and not isinstance(params, WristFTParams):
            raise ValueError(f"params must be WristFTParams, got {type(params).__name__}")
        self.params = params or WristFTParams()
        self._rng: np.random.Generator | None = None

    def reset(self, rng: np.random.Generator, payload_mass: float = 0.0,
              payload_com: object = (0.0, 0.0, 0.0)) -> WristFT:
        """Start an episode: draw the payload errors and the sensor offset from ``rng``.

        Args:
            rng: the episode's Generator (all randomness comes from it).
            payload_mass: true mass below the sensor, kg (gripper + held object).
            payload_com: its true centre of mass in the sensor frame, m.
        """
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        p = self.params
        self._rng = rng
        self.mass_error = float(rng.normal(0.0, p.mass_error)) if p.mass_error > 0 else 0.0
        self.com_error = (rng.normal(0.0, p.com_error, 3) if p.com_error > 0 else np.zeros(3))
        self._bias = (rng.normal(0.0, p.accuracy / 3.0, 3) if p.accuracy > 0 else np.zeros(3))
        self._offset = np.zeros(3)
        self._filt = np.zeros(3)
        self._started = False
        self.set_payload(payload_mass, payload_com)
        return self

    def set_payload(self, mass: float, com: object) -> None:
        """The true payload changed (e.g. the gripper let go); its configured value keeps the
        episode's errors: ``mass + mass_error``, ``com + com_error`` (floored at 0 kg)."""
        if isinstance(mass, bool) or not math.isfinite(float(mass)) or float(mass) < 0:
            raise ValueError(f"payload_mass must be a finite number >= 0 kg, got {mass!r}")
        self.payload_mass = float(mass)
        self.payload_com = _vec3(com, "payload_com")
        self.configured_mass = max(0.0, self.payload_mass + self.mass_error)
        self.configured_com = self.payload_com + self.com_error

    @property
    def configured_payload(self) -> tuple[float, np.ndarray]:
        """(mass kg, centre of mass in the sensor frame m) a UR program would have set."""
        return self.configured_mass, self.configured_com.copy()

    def _alpha(self, dt: float) -> float:
        tau = self.params.filter_tau
        return 1.0 if tau <= 0 else dt / (tau + dt)

    def measure(self, true_force_world: object, payload_accel_world: object,
                gripper_rotation: object, dt: float, omega_world: object = None,
                alpha_world: object = None) -> np.ndarray:
        """One tick: the force estimate (world frame, N) the release compares with f_r.

        Args:
            true_force_world: exact external force at the wrist (the env's estimate), N.
            payload_accel_world: the payload's specific force ``a - g`` (accelerometer), m/s^2.
            gripper_rotation: sensor-to-world rotation (3x3 or 9 numbers).
            dt: time since the previous tick, s (> 0).
            omega_world, alpha_world: gripper angular velocity / acceleration, rad/s, rad/s^2
                (optional: with them the centre-of-mass error's inertial force is included).
        """
        if self._rng is None:
            raise RuntimeError("WristFT.measure() called before reset(rng)")
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        p = self.params
        f = _vec3(true_force_world, "true_force_world")
        sf = _vec3(payload_accel_world, "payload_accel_world")
        rot = _rotation(gripper_rotation)
        err = self.mass_error * sf if self.mass_error else np.zeros(3)
        if omega_world is not None and alpha_world is not None:
            w, al = _vec3(omega_world, "omega_world"), _vec3(alpha_world, "alpha_world")
            c_true, c_conf = rot @ self.payload_com, rot @ self.configured_com
            err = err + (self.configured_mass * (np.cross(al, c_conf)
                                                 + np.cross(w, np.cross(w, c_conf)))
                         - self.payload_mass * (np.cross(al, c_true)
                                                + np.cross(w, np.cross(w, c_true))))
        a = self._alpha(float(dt))
        raw_s = rot.T @ (f + err) + self._bias
        self._clean_s = raw_s
        if p.drift > 0 or p.precision > 0:
            z = self._rng.standard_normal(6)
            self._bias = self._bias + p.drift * math.sqrt(dt) * z[3:]
            sigma_out = p.precision / 3.0
            raw_s = raw_s + sigma_out * math.sqrt((2.0 - a) / a) * z[:3]
        meas = rot @ (raw_s - self._offset)
        if not self._started:
            self._filt, self._started = meas, True
        else:
            self._filt = self._filt + a * (meas - self._filt)
        self._rot = rot
        return self._filt.copy()

    def zero(self) -> None:
        """Tare the sensor at the current reading (URScript ``zero_ftsensor()``).

        The tare is taken as the reading's noise-free value at the last :meth:`measure` (offset,
        drift so far, payload error and whatever force acts then), i.e. a tare averaged long enough
        that its own noise is negligible; the filtered output restarts at 0. A no-op when
        ``params.zeroing`` is False (the "ideal" profile) or before the first :meth:`measure`.
        """
        if self._rng is None:
            raise RuntimeError("WristFT.zero() called before reset(rng)")
        if not self.params.zeroing or not self._started:
            return
        self._offset = self._clean_s.copy()
        self._filt = np.zeros(3)
