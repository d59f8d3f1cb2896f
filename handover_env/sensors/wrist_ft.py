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

Deterministic given the Generator passed to :meth:`reset` (normals drawn in blocks of 256 ticks);
the "ideal" profile (no errors, no zeroing) draws no random numbers and returns the filtered input
(the env then bypasses the model altogether: its own exact path).

Steps 2-4 are one compiled kernel, :func:`handover_env.sensors.ft_sense.ft_sense`, on the
sensor's state array (:attr:`WristFT.state`). Two entry points: :meth:`WristFT.measure` (checked
arrays; it adds the payload error of step 1 itself) and :meth:`WristFT.sense`, without checks,
which takes the force already compensated with the configured payload (the env computes it with
:attr:`WristFT.configured_mass` / :attr:`WristFT.configured_com` in the same formula as the exact
estimate, and calls the kernel from its own compiled tick, :mod:`handover_env.envs.wrist_tick`);
validation is at :meth:`WristFT.reset` and :meth:`WristFT.set_tick`.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.sensors import ft_sense as fs
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
        #: the sensor's state for the compiled tick (see :mod:`handover_env.sensors.ft_sense`)
        self.state = np.zeros(fs.SIZE)

    def reset(self, rng: np.random.Generator, payload_mass: float = 0.0,
              payload_com: object = (0.0, 0.0, 0.0), dt: float = 0.005) -> WristFT:
        """Start an episode: draw the payload errors and the sensor offset from ``rng``.

        Args:
            rng: the episode's Generator (all randomness comes from it).
            payload_mass: true mass below the sensor, kg (gripper + held object).
            payload_com: its true centre of mass in the sensor frame, m.
            dt: the tick interval of :meth:`sense` (see :meth:`set_tick`), s.
        """
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        p = self.params
        self._rng = rng
        self.mass_error = float(rng.normal(0.0, p.mass_error)) if p.mass_error > 0 else 0.0
        self.com_error = (rng.normal(0.0, p.com_error, 3) if p.com_error > 0 else np.zeros(3))
        st = self.state
        st[:] = 0.0
        if p.accuracy > 0:
            st[fs.BIAS:fs.BIAS + 3] = rng.normal(0.0, p.accuracy / 3.0, 3)
        st[fs.ZI] = 6 * fs.BLOCK  # no normals drawn yet
        self.set_tick(dt)
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

    def set_tick(self, dt: float) -> None:
        """Fix the tick interval of :meth:`sense` (s, > 0): the filter gain, the white-noise scale
        that gives the filtered reading ``precision / 3`` per axis, and the drift step."""
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        p = self.params
        dt = float(dt)
        tau = p.filter_tau
        a = 1.0 if tau <= 0 else dt / (tau + dt)
        self._dt = dt
        st = self.state
        st[fs.GAIN] = a
        st[fs.NOISE_SCALE] = p.precision / 3.0 * math.sqrt((2.0 - a) / a)
        st[fs.DRIFT_STEP] = p.drift * math.sqrt(dt)
        self.draws = p.drift > 0 or p.precision > 0
        st[fs.DRAWS] = float(self.draws)

    def refill(self) -> None:
        """Draw the next block of normals if the sensor draws and has used up its block (call
        before each tick; the block is 256 ticks of six standard normals from the rng)."""
        st = self.state
        if self.draws and st[fs.ZI] >= 6 * fs.BLOCK:
            st[fs.NORMALS:] = self._rng.standard_normal(6 * fs.BLOCK)  # type: ignore[union-attr]
            st[fs.ZI] = 0.0

    def sense(self, gx: float, gy: float, gz: float, r: np.ndarray) -> tuple[float, float, float]:
        """The fast path, one tick: the filtered reading (world frame, N) from the force the robot
        computes with its *configured* payload (``gx, gy, gz``: the external force estimate
        ``R (m_c a_s - F_s) + m_c (α × c_c + ω × (ω × c_c))``, world frame) and the sensor-to-world
        rotation ``r`` (a float64 array of 9 numbers, row-major).

        Plain floats, no checks: :meth:`reset` and :meth:`set_tick` validated everything. Steps 2-4
        of the module docstring: offset + drift + white noise in the sensor frame, the tare, the
        filter. Uses the tick interval of :meth:`set_tick`.
        """
        self.refill()
        return fs.ft_sense(self.state, gx, gy, gz, r, 0)

    def measure(self, true_force_world: object, payload_accel_world: object,
                gripper_rotation: object, dt: float, omega_world: object = None,
                alpha_world: object = None) -> np.ndarray:
        """One tick, checked: the force estimate (world frame, N) the release compares with f_r.

        Args:
            true_force_world: exact external force at the wrist (the env's estimate), N.
            payload_accel_world: the payload's specific force ``a - g`` (accelerometer), m/s^2.
            gripper_rotation: sensor-to-world rotation (3x3 or 9 numbers).
            dt: time since the previous tick, s (> 0).
            omega_world, alpha_world: gripper angular velocity / acceleration, rad/s, rad/s^2
                (optional: with them the centre-of-mass error's inertial force is included).

        Adds the configured payload's error (step 1 of the module docstring) and calls
        :meth:`sense`.
        """
        if self._rng is None:
            raise RuntimeError("WristFT.measure() called before reset(rng)")
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
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
        if float(dt) != self._dt:
            self.set_tick(float(dt))
        g = (f + err).tolist()
        return np.array(self.sense(g[0], g[1], g[2], np.ascontiguousarray(rot).reshape(9)))

    def zero(self) -> None:
        """Tare the sensor at the current reading (URScript ``zero_ftsensor()``).

        The tare is taken as the reading's noise-free value at the last :meth:`sense` (offset,
        drift so far, payload error and whatever force acts then), i.e. a tare averaged long enough
        that its own noise is negligible; the filtered output restarts at 0. A no-op when
        ``params.zeroing`` is False (the "ideal" profile) or before the first :meth:`sense`.
        """
        if self._rng is None:
            raise RuntimeError("WristFT.zero() called before reset(rng)")
        st = self.state
        if not self.params.zeroing or st[fs.STARTED] == 0.0:
            return
        st[fs.OFFSET:fs.OFFSET + 3] = st[fs.CLEAN:fs.CLEAN + 3]
        st[fs.FILT:fs.FILT + 3] = 0.0
