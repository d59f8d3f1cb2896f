"""Sensor and controller parameters of the robot the paper had, and the three profiles.

Data only: three frozen dataclasses and their documented ranges. :class:`CameraParams` feeds
:class:`handover_env.sensors.camera.Camera` (the ZED 2i + ZED SDK 4.0 body tracking at 30 Hz,
paper Sec. IV-A and V-B), :class:`WristFTParams` feeds
:class:`handover_env.sensors.wrist_ft.WristFT` (the UR5e's built-in wrist force/torque sensor),
:class:`ControllerParams` holds the controller placeholders the env's integrator will use (the
paper's constant M, the command delay, the UR5e's speed limits). Every number's source is in the
``FIELDS`` tables below and in docs/sensing.md.

Profiles (:func:`make_profile`):

* ``"paper"``: every field at its documented value (vendor documents, or derived from the
  recordings by ``handover-data sensing``).
* ``"ideal"``: today's simulated world exactly: no latency, noise, lost frames or drift, the exact
  payload, no zeroing, the controller's Λ(q) inertia, no command delay, no extra limits.
* ``"randomized"``: each numeric field drawn once, uniformly from its ``random`` range, with the
  given ``numpy.random.Generator`` (seeded, so deterministic).

Overrides: a dict ``{"camera": {...}, "wrist": {...}, "controller": {...}}`` of field values,
checked as the env's ``person={...}`` settings are: a mapping, known keys, real finite numbers
(bools are not), each within its stated range; the error names the field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple

import numpy as np

from handover_env.numbers import checked_number, fits_float, is_real_number, shown

G = 9.81


class Field(NamedTuple):
    """A parameter's valid range, randomization range, unit and source."""

    lo: float
    hi: float
    random: tuple[float, float]
    unit: str
    source: str


#: ZED 2i + ZED SDK 4.0 body tracking (paper Sec. IV-A, V-B). Derived values:
#: handover_eval/calibration/sensing.py.
CAMERA_FIELDS: dict[str, Field] = {
    "rate_hz": Field(1.0, 120.0, (30.0, 30.0), "Hz",
                     "paper Sec. V-B: base pose captured at 30 Hz"),
    "latency": Field(0.0, 0.5, (0.066, 0.133), "s",
                     "Stereolabs support 'What is the latency of the ZED camera?': 66-100 ms at "
                     "30 fps (2-3 frames) for delivery, plus at most one frame (33 ms) of body "
                     "tracking, which kept up with 30 Hz in the paper"),
    "pelvis_sigma": Field(0.0, 0.2, (0.0025, 0.0076), "m",
                          "derived: white noise with the recordings' pelvis jitter (sensing.py)"),
    "pelvis_rho": Field(0.0, 0.999, (0.0, 0.0), "",
                        "derived: 0, an AR(1) cannot fit the recorded residual (sensing.py)"),
    "hand_sigma": Field(0.0, 0.5, (0.03, 0.09), "m",
                        "derived: ZED hand - OptiTrack object residual, carrying (sensing.py)"),
    "hand_rho": Field(0.0, 0.999, (0.90, 0.98), "",
                      "derived: lag-1 autocorrelation of that residual (sensing.py)"),
    "lost_fraction": Field(0.0, 0.5, (0.0, 0.01), "",
                           "derived: fraction of frames in tracker re-fit bursts (sensing.py)"),
    "lost_run": Field(1.0, 300.0, (1.0, 5.0), "frames",
                      "derived: mean length of a re-fit burst (sensing.py)"),
}

#: UR5e built-in wrist F/T sensor (UR5e technical specifications, "Force sensing, tool flange").
WRIST_FIELDS: dict[str, Field] = {
    "precision": Field(0.0, 20.0, (2.5, 4.5), "N",
                       "UR5e datasheet: force precision 3.5 N; read as 3 sigma per axis (the "
                       "ISO 9283 repeatability convention of the same datasheet)"),
    "accuracy": Field(0.0, 20.0, (3.0, 5.0), "N",
                      "UR5e datasheet: force accuracy 4.0 N; a per-episode offset of 3 sigma per "
                      "axis, removed by zero()"),
    "filter_tau": Field(0.0, 0.2, (0.005, 0.03), "s",
                        "UR publishes no bandwidth ('very fast, high mechanical bandwidth', UR in "
                        "Universal_Robots_ROS_Driver#269); the env's force_filter_tau"),
    "drift": Field(0.0, 5.0, (0.0, 0.5), "N/sqrt(s)",
                   "random-walk bias: ~4 N in ~5 min at rest (Universal_Robots_ROS_Driver#633), "
                   "4 N / sqrt(300 s)"),
    "mass_error": Field(0.0, 2.0, (0.05, 0.25), "kg",
                        "sigma of the configured payload mass: force accuracy / (3 g), the "
                        "resolution of a payload estimated with this sensor"),
    "com_error": Field(0.0, 0.2, (0.0, 0.015), "m",
                       "sigma per axis of the configured centre of mass: torque accuracy 0.3 N m "
                       "/ (3 g x 1.33 kg gripper + bottle)"),
}

#: Controller placeholders for the integrator (not used by the sensor models).
CONTROLLER_FIELDS: dict[str, Field] = {
    "inertia": Field(0.0, 50.0, (2.0, 8.0), "kg",
                     "0 = the controller's Λ(q); paper Sec. III-A sets M constant without a value: "
                     "placeholder trace(Λ)/3 = 4.7 kg of the scene's UR5e at READY_POS"),
    "command_delay": Field(0.0, 0.1, (0.002, 0.010), "s",
                           "one 200 Hz control period (paper Sec. V-B); the UR controller itself "
                           "runs at 500 Hz (2 ms, URScript manual, module motion)"),
    "control_rate_hz": Field(1.0, 1000.0, (200.0, 200.0), "Hz", "paper Sec. V-B: 200 Hz"),
    "joint_speed_limit": Field(0.0, 10.0, (math.pi, math.pi), "rad/s",
                               "0 = none; UR5e datasheet: 180 deg/s on every joint"),
    "joint_accel_limit": Field(0.0, 100.0, (0.0, 0.0), "rad/s^2",
                               "0 = none: the UR5e datasheet gives no joint acceleration limit "
                               "(the env's torque limits bound it)"),
    "tcp_speed_limit": Field(0.0, 5.0, (1.0, 1.0), "m/s",
                             "0 = none; UR5e datasheet: typical TCP speed 1 m/s"),
}


def check_value(group: str, table: Mapping[str, Field], name: str, value: object) -> float:
    """``value`` as a float if it is a valid ``group.name``; else ValueError naming the field (an
    integer too large for a float included)."""
    lo, hi, _, unit, source = table[name]
    return checked_number(f"{group} {name}", value, lo, hi, unit, source)


def _validate(obj: Any, group: str, table: Mapping[str, Field]) -> None:
    for name in table:
        object.__setattr__(obj, name, check_value(group, table, name, getattr(obj, name)))


@dataclass(frozen=True)
class CameraParams:
    """The body tracker seen by the agent (defaults: the ``"paper"`` profile).

    Attributes:
        rate_hz: frame rate; one :meth:`Camera.frame` call per frame.
        latency: capture-to-availability delay, s (exposure, transport, inference, fitting).
        pelvis_sigma, pelvis_rho: pelvis keypoint noise, m, and its frame-to-frame correlation.
        hand_sigma, hand_rho: right-hand keypoint noise, m, and its correlation.
        lost_fraction: long-run fraction of frames in which the tracker loses the body.
        lost_run: mean length of a loss, frames (geometric).
    """

    rate_hz: float = 30.0
    latency: float = 0.100
    pelvis_sigma: float = 0.0051
    pelvis_rho: float = 0.0
    hand_sigma: float = 0.0625
    hand_rho: float = 0.954
    lost_fraction: float = 0.00125
    lost_run: float = 1.81

    def __post_init__(self) -> None:
        _validate(self, "camera", CAMERA_FIELDS)


@dataclass(frozen=True)
class WristFTParams:
    """The UR5e wrist F/T sensor and the configured payload (defaults: ``"paper"``).

    Attributes:
        precision: datasheet force precision, N (3 sigma per axis of the reading's noise).
        accuracy: datasheet force accuracy, N (3 sigma per axis of an offset zeroing removes).
        filter_tau: first-order low-pass time constant of the reading, s (0 = none).
        drift: bias random-walk intensity, N/sqrt(s) per axis.
        mass_error: sigma of the configured payload mass error, kg.
        com_error: sigma per axis of the configured payload centre-of-mass error, m.
        zeroing: whether :meth:`WristFT.zero` tares the sensor (a UR program's zero_ftsensor()).
    """

    precision: float = 3.5
    accuracy: float = 4.0
    filter_tau: float = 0.015
    drift: float = 0.24
    mass_error: float = 0.136
    com_error: float = 0.0077
    zeroing: bool = True

    def __post_init__(self) -> None:
        _validate(self, "wrist", WRIST_FIELDS)
        if not isinstance(self.zeroing, (bool, np.bool_)):
            raise ValueError(f"wrist zeroing must be True or False, got {shown(self.zeroing)}")
        object.__setattr__(self, "zeroing", bool(self.zeroing))


@dataclass(frozen=True)
class ControllerParams:
    """Controller placeholders (defaults: ``"paper"``); see :data:`CONTROLLER_FIELDS`."""

    inertia: float = 4.7
    command_delay: float = 0.005
    control_rate_hz: float = 200.0
    joint_speed_limit: float = math.pi
    joint_accel_limit: float = 0.0
    tcp_speed_limit: float = 1.0

    def __post_init__(self) -> None:
        _validate(self, "controller", CONTROLLER_FIELDS)


@dataclass(frozen=True)
class SensorProfile:
    """One complete set: ``camera``, ``wrist``, ``controller`` and the profile's ``name``."""

    name: str
    camera: CameraParams
    wrist: WristFTParams
    controller: ControllerParams


PROFILES = ("paper", "ideal", "randomized")
_GROUPS: dict[str, tuple[type, Mapping[str, Field]]] = {
    "camera": (CameraParams, CAMERA_FIELDS),
    "wrist": (WristFTParams, WRIST_FIELDS),
    "controller": (ControllerParams, CONTROLLER_FIELDS),
}

IDEAL = SensorProfile(
    "ideal",
    CameraParams(latency=0.0, pelvis_sigma=0.0, pelvis_rho=0.0, hand_sigma=0.0, hand_rho=0.0,
                 lost_fraction=0.0, lost_run=1.0),
    WristFTParams(precision=0.0, accuracy=0.0, drift=0.0, mass_error=0.0, com_error=0.0,
                  zeroing=False),
    ControllerParams(inertia=0.0, command_delay=0.0, joint_speed_limit=0.0,
                     joint_accel_limit=0.0, tcp_speed_limit=0.0),
)
PAPER = SensorProfile("paper", CameraParams(), WristFTParams(), ControllerParams())


def check_overrides(overrides: object) -> dict[str, dict[str, object]]:
    """Validate ``{"camera": {...}, "wrist": {...}, "controller": {...}}`` field by field."""
    if not isinstance(overrides, Mapping):
        raise ValueError(
            f"sensor overrides must be a dict of {sorted(_GROUPS)}, got {type(overrides).__name__}"
        )
    unknown = sorted(str(k) for k in overrides if k not in _GROUPS)
    if unknown:
        raise ValueError(f"unknown sensor override group(s) {unknown}; known: {sorted(_GROUPS)}")
    out: dict[str, dict[str, object]] = {}
    for group, values in overrides.items():
        cls, table = _GROUPS[group]
        if not isinstance(values, Mapping):
            raise ValueError(f"{group} overrides must be a dict, got {type(values).__name__}")
        known = [f.name for f in fields(cls)]
        bad = sorted(str(k) for k in values if k not in known)
        if bad:
            raise ValueError(f"unknown {group} field(s) {bad}; known: {known}")
        for name, value in values.items():
            if name in table:
                check_value(group, table, name, value)
        out[group] = dict(values)
    return out


def make_profile(name: str, overrides: object = None,
                 rng: np.random.Generator | None = None) -> SensorProfile:
    """The ``"paper"``, ``"ideal"`` or ``"randomized"`` profile, with ``overrides`` applied.

    Args:
        name: one of :data:`PROFILES`.
        overrides: see :func:`check_overrides`; applied last (also over randomized draws).
        rng: required for ``"randomized"`` (one uniform draw per numeric field, in field order).

    Raises:
        ValueError: unknown profile, missing generator, or a bad override (naming the field).
    """
    if name not in PROFILES:
        raise ValueError(f"unknown sensor profile {name!r}; known: {list(PROFILES)}")
    checked = check_overrides(overrides) if overrides is not None else {}
    if name == "ideal":
        base = IDEAL
    elif name == "paper":
        base = PAPER
    else:
        if not isinstance(rng, np.random.Generator):
            raise ValueError("the 'randomized' profile needs a numpy.random.Generator (rng=...)")
        drawn = {}
        for group, (cls, table) in _GROUPS.items():
            values = {k: float(rng.uniform(*f.random)) for k, f in table.items()}
            drawn[group] = cls(**values)
        base = SensorProfile("randomized", drawn["camera"], drawn["wrist"], drawn["controller"])
    parts = {g: replace(getattr(base, g), **checked.get(g, {})) for g in _GROUPS}
    return SensorProfile(name, parts["camera"], parts["wrist"], parts["controller"])


def _set_by(kwarg: str, legacy: dict[str, dict[str, object]], group: str,
            **values: object) -> None:
    """Add the ``group`` fields that the env kwarg ``kwarg`` sets to ``legacy``, each checked; a
    bad one is a ValueError naming both the kwarg and the field."""
    for name, value in values.items():
        try:
            check_value(group, _GROUPS[group][1], name, value)
        except ValueError as exc:
            raise ValueError(f"{kwarg} (the {group} {name}): {exc}") from None
    legacy.setdefault(group, {}).update(values)


def sensing_settings(sensing: object, sensors: object = None, obs_noise: object = None,
                     obs_latency: object = None, force_filter_tau: object = None,
                     frame_rate: float = 30.0) -> tuple[str, dict[str, dict[str, object]]]:
    """The env's sensing kwargs as ``(profile name, checked overrides)``.

    ``sensors`` is ``{"camera": {...}, "wrist": {...}, "controller": {...}}``. The env's older
    kwargs are camera / wrist overrides: ``obs_noise`` (m) sets both keypoints' white noise
    (``pelvis_sigma = hand_sigma = obs_noise``, ``pelvis_rho = hand_rho = 0``), ``obs_latency``
    (whole frames) sets ``latency = obs_latency / frame_rate``, ``force_filter_tau`` (s) sets the
    wrist ``filter_tau``. Giving a field both ways is an error.

    Raises:
        ValueError: unknown profile, a bad override (naming the field), or a field given twice.
    """
    if not isinstance(sensing, str) or sensing not in PROFILES:
        raise ValueError(f"sensing must be one of {list(PROFILES)}, got {sensing!r}")
    checked = check_overrides(sensors) if sensors is not None else {}
    legacy: dict[str, dict[str, object]] = {}
    if obs_noise is not None:
        if (not is_real_number(obs_noise) or not fits_float(obs_noise)
                or not math.isfinite(float(obs_noise)) or obs_noise < 0):
            raise ValueError(
                f"obs_noise must be a finite number >= 0 (m), got {shown(obs_noise)}")
        _set_by("obs_noise", legacy, "camera", pelvis_sigma=float(obs_noise),
                hand_sigma=float(obs_noise), pelvis_rho=0.0, hand_rho=0.0)
    if obs_latency is not None:
        if (not is_real_number(obs_latency) or not fits_float(obs_latency)
                or not math.isfinite(float(obs_latency))
                or int(obs_latency) != obs_latency or obs_latency < 0):
            raise ValueError(
                f"obs_latency must be a whole number of frames >= 0, got {shown(obs_latency)}")
        _set_by("obs_latency", legacy, "camera", latency=int(obs_latency) / frame_rate)
    if force_filter_tau is not None:
        _set_by("force_filter_tau", legacy, "wrist", filter_tau=force_filter_tau)
    legacy = check_overrides(legacy)
    out = {g: dict(v) for g, v in checked.items()}
    for group, values in legacy.items():
        both = sorted(set(values) & set(out.get(group, {})))
        if both:
            raise ValueError(
                f"{group} field(s) {both} given both in sensors= and by obs_noise / obs_latency / "
                "force_filter_tau; give each once")
        out.setdefault(group, {}).update(values)
    return sensing, out


def profile_summary(profile: SensorProfile) -> dict[str, object]:
    """The profile as a JSON-serialisable dict: ``{"name", "camera": {...}, "wrist": {...},
    "controller": {...}}`` (every field; the env reports it in the reset's ``info``)."""
    out: dict[str, object] = {"name": profile.name}
    for group in _GROUPS:
        params = getattr(profile, group)
        out[group] = {f.name: getattr(params, f.name) for f in fields(params)}
    return out
