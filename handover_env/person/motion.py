"""Who walks past the giver: scripted walkers, one model for the data and the env.

The paper's receiver (Sec. IV-A, "Data Collection"; Sec. V-A) walks toward the giver, passes at
their side and takes the object on the move. A walker (:class:`WalkerParams`, drawn by
:func:`sample_walker`) and its walk (:mod:`handover_env.person.trajectory`: the pelvis track,
the shoulder and the hand along it) drive

* the synthetic dataset (:mod:`handover_env.person.synthetic`), and
* the env's scripted ID/OOD receivers (:mod:`handover_env.person.receiver`),

so the simulated people and the demonstrations cannot drift apart.

Frame (the public dataset's): z up, floor at z = 0, giver/robot near the origin facing +x. The
receiver starts about 2.5 m away on the giver's right-front, walks toward -x, passes the giver's
side along ``y = pass_y`` (about -0.6 .. -1.2) and stops being recorded near ``x = -0.8``. While
walking toward -x (heading yaw ~ pi) the receiver's RIGHT side, and right hand, face +y: the giver.

All randomness lives in :func:`sample_walker`;
:func:`~handover_env.person.trajectory.base_trajectory` and the body functions are deterministic
and pure numpy, so a seeded ``np.random.Generator`` reproduces a walker exactly.

Calibration. Every distribution in :func:`sample_walker` is a piecewise-linear quantile function
built from summary STATISTICS of the public Dynamic Handover Dataset (875-recording development
copy; quantiles over recordings, never per-recording values): the receiver pelvis (ZED BODY_34
joint 0) start point in polar form, its per-recording median walking speed, its y at the moment
of transfer, and the shoulder height (joint 12). Body proportions (shoulder, hand) are expressed
as fractions of body height, fitted to the same statistics with the standard anthropometric ratio
shoulder height = 0.818 x body height.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from handover_env.numbers import checked_number, is_real_number

# --------------------------------------------------------------------------------------------
# Calibration tables: (cumulative probability, value) pairs of quantiles over recordings.
# Source: public Dynamic Handover Dataset, ID recordings ("motion_normal_*"), statistics only.
# --------------------------------------------------------------------------------------------
_P = (0.0, 0.01, 0.05, 0.25, 0.50, 0.75, 0.95, 0.99, 1.0)
#: Start of the walk in polar form around the giver: bearing (deg) and distance (m) of the pelvis.
#: Data: bearing 1%/50%/99% = -60.4/-19.8/1.6 deg, distance 1.70/2.51/3.02 m, rank correlation ~0.5.
START_BEARING_DEG_Q = (_P, (-63.0, -60.4, -48.8, -34.7, -19.8, -7.9, -0.9, 1.6, 4.0))
START_DISTANCE_Q = (_P, (1.55, 1.70, 1.93, 2.28, 2.51, 2.70, 2.88, 3.02, 3.10))
START_RANK_CORRELATION = 0.5
#: Bounding box of the data's start points (x range, y range), m.
START_BOX = ((0.73, 3.13), (-1.86, 0.17))
_START_CANDIDATES = 16
#: Initial walking direction relative to the straight line to the passing line (deg, + = toward
#: +y). Data: from the first 8 frames of the smoothed pelvis track; 5%/50%/75%/95% = -31/11/38/81
#: deg; the upper tail is trimmed to 62 (95%) .. 70 deg so that turns stay below ~3 rad/s.
START_TURN_DEG_Q = (
    (0.0, 0.05, 0.25, 0.5, 0.75, 0.95, 1.0),
    (-40.0, -31.2, -3.8, 10.9, 37.7, 62.0, 70.0),
)
#: Per-recording median pelvis speed (m/s). Data: 0.57 .. 1.13, median 0.83.
SPEED_Q = (_P, (0.58, 0.633, 0.691, 0.769, 0.831, 0.90, 0.996, 1.078, 1.12))
#: Pelvis y at the moment of transfer (m). Data: 1%/50%/99% = -1.20/-0.92/-0.58.
PASS_Y_Q = (_P, (-1.25, -1.197, -1.108, -0.985, -0.92, -0.856, -0.748, -0.62, -0.58))
#: Body height (m) = right-shoulder height / 0.818; data shoulder z 1.37 .. 1.44, median 1.41.
HEIGHT_Q = (
    (0.0, 0.05, 0.25, 0.5, 0.75, 0.95, 1.0),
    (1.68, 1.70, 1.715, 1.725, 1.735, 1.746, 1.765),
)
#: The recordings end when the pelvis passes x = -0.77 .. -0.80.
END_X_RANGE = (-0.80, -0.765)

# Body proportions as fractions of height (anthropometry, fitted to the dataset's joint statistics).
SHOULDER_HEIGHT_RATIO = 0.818  # acromion height / body height; data shoulder z median 1.41 m
SHOULDER_HALF_WIDTH_RATIO = 0.10  # lateral pelvis -> right shoulder; data median 0.17 m
HAND_REST_HEIGHT_RATIO = 0.50  # hand z while walking; data median 0.86 m
HAND_REST_LATERAL_RATIO = 0.155  # lateral pelvis -> right hand while walking; data median 0.27 m
HAND_SWING_RATIO = 0.06  # forward/back arm-swing amplitude; data hand forward std ~0.11 m
ARM_REACH_RATIO = (
    0.386  # shoulder -> grip centre (upper arm 0.186 + forearm 0.146 + half hand 0.054)
)
DEFAULT_HEIGHT = 1.725

KINDS = ("id", "ood")
OOD_MODES = ("wander", "pause")

# --------------------------------------------------------------------------------------------
# OOD walkers (paper Sec. V-A: the receiver wanders or pauses), calibrated to the recorded OOD
# walks ("motion_variation_*") of the calibration half (Table I folds 0-4) on the statistics of
# handover_eval.calibration.walks: total heading change, detour, speed CV, pause duration
# (docs/calibration/walkers.md, written by `handover-data walk-stats`). Half of the
# OOD walkers mainly wander (a wide looping meander), half mainly pause (a short stop on a path
# that first swings out sideways): the recorded OOD walks range from loops without a stop to
# stops on a path with a single wide detour. Uniform ranges (low, high) per mode (a fixed value
# where low = high); the ID walkers do not use them.
# --------------------------------------------------------------------------------------------
OOD_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    # Mainly wanders: leaves the start sideways (|start_turn| 46 .. 86 deg, long start tangent),
    # then a meander of 0.5 .. 0.9 m (loops where wander_loop x amplitude is large enough) over a
    # wavelength of 3 .. 4.5 m, faded out by x = 0.7 (the recorded
    # OOD walks are back on the passing line by x ~ 0.5), and a larger slow speed drift.
    "wander": {
        "wander_amplitude": (0.5, 0.9),
        "wander_wavelength": (3.0, 4.5),
        "wander_loop": (0.3, 0.7),
        "wander_fade_x": (0.7, 0.7),
        "start_bulge": (2.0, 3.0),
        "start_turn": (0.8, 1.5),
        "drift_amplitude": (0.15, 0.35),
    },
    # Mainly pauses: a stop of 0 .. 0.6 s between 0.4 .. 0.8 s ramps (the recorded pauses below
    # 0.25 m/s last 0.70 s, median; the ramps add ~0.4 s below that speed), after a wide sideways
    # start (|start_turn| 57 .. 86 deg) and with at most a slight meander.
    "pause": {
        "pause_time": (0.8, 2.2),
        "pause_duration": (0.0, 0.6),
        "pause_ramp": (0.4, 0.8),
        "wander_amplitude": (0.0, 0.15),
        "wander_wavelength": (2.5, 4.5),
        "wander_loop": (0.0, 1.0),
        "wander_fade_x": (0.5, 0.5),
        "start_bulge": (3.0, 4.5),
        "start_turn": (1.0, 1.5),
        "drift_amplitude": (0.05, 0.2),
    },
}
#: Which of the sampler's uniforms ``g`` each OOD field is drawn from (those of the ID fields).
OOD_UNIFORM = {
    "drift_amplitude": 0,
    "pause_time": 4,
    "pause_duration": 5,
    "pause_ramp": 6,
    "wander_amplitude": 7,
    "wander_wavelength": 8,
    "wander_loop": 10,
    "wander_fade_x": 4,
    "start_bulge": 12,
    "start_turn": 11,
}
#: OOD fields drawn with either sign: OOD_RANGES gives the range of their magnitude.
OOD_SYMMETRIC = frozenset({"start_turn"})

# --------------------------------------------------------------------------------------------
# Physical ranges of a walker's fields. WalkerParams refuses a value outside them, naming the
# field and the range; each range holds everything the sampler draws with a wide margin.
# --------------------------------------------------------------------------------------------
#: Half-size of the scene's floor plane, m (handover_env/assets/scene.xml: floor size="6 6").
FLOOR_HALF_SIZE = 6.0
#: How far the body reaches out sideways from the pelvis while walking, m: the right hand's rest
#: offset for the tallest body (HAND_REST_LATERAL_RATIO x 2.3 m = 0.36 m), rounded up.
BODY_HALF_WIDTH = 0.4
#: The pelvis track stays within +-PELVIS_LIMIT m in x and y, so that the whole body stays on
#: the floor (:func:`base_trajectory` refuses a walk that would leave it).
PELVIS_LIMIT = FLOOR_HALF_SIZE - BODY_HALF_WIDTH
#: The widest lateral gait sway, m (the sampler draws 0.006 .. 0.02; 0.1 m is a staggering gait).
MAX_SWAY = 0.1
#: The walk's points (start, passing line, end, convergence and fade x) lie within
#: +-WALK_HALF_SIZE m: the pelvis limit less the widest sway.
WALK_HALF_SIZE = PELVIS_LIMIT - MAX_SWAY
#: Longest a walk may take, s: six times the env's longest episode (StaticHandover-v0: 600
#: steps at 30 Hz = 20 s); the recordings last 2.3 .. 9.6 s (69 .. 287 frames).
MAX_WALK_TIME = 120.0
#: Walking speeds, m/s: a shuffle to a brisk walk (people start to run at about 2 m/s; the
#: recordings' per-recording medians are 0.57 .. 1.13). The env's ``speed`` option uses it too.
SPEED_RANGE = (0.1, 2.5)
#: Human body heights, m (as :meth:`handover_env.person.skeleton.BodyDims.from_height`).
HEIGHT_RANGE = (1.0, 2.3)
#: (low, high, unit, where the range comes from) of every numeric WalkerParams field.
FIELD_RANGES: dict[str, tuple[float, float, str, str]] = {
    "speed": (*SPEED_RANGE, "m/s", "walking speeds, SPEED_RANGE"),
    "pass_y": (-WALK_HALF_SIZE, 0.0, "m",
               "on the giver's right (y <= 0, as in every recording) and on the floor"),
    "end_x": (-WALK_HALF_SIZE, WALK_HALF_SIZE, "m", "on the floor (WALK_HALF_SIZE)"),
    "height": (*HEIGHT_RANGE, "m", "human body heights, HEIGHT_RANGE"),
    "approach_x": (-WALK_HALF_SIZE, WALK_HALF_SIZE, "m", "on the floor (WALK_HALF_SIZE)"),
    "start_turn": (-math.pi / 2, math.pi / 2, "rad",
                   "a walker that turns more than 90 deg away starts by walking away"),
    "start_bulge": (0.25, 5.0, "",
                    "sampled 1.0 .. 1.6 (ID), 2.0 .. 4.5 (OOD_RANGES); longer start tangents "
                    "swing the path far out"),
    "step_length_ratio": (0.15, 0.5, "", "step length / height of walking: shuffle to stride"),
    "sway_amplitude": (0.0, MAX_SWAY, "m", "lateral gait sway, MAX_SWAY"),
    "speed_ripple": (0.0, 0.5, "", "relative; with drift_amplitude below 0.9"),
    "drift_amplitude": (0.0, 0.5, "", "relative; with speed_ripple below 0.9"),
    "drift_frequency": (0.01, 1.0, "Hz", "a slow variation, below the ~1.7 Hz step frequency"),
    "drift_phase": (-2 * math.pi, 2 * math.pi, "rad", "a phase"),
    "gait_phase": (-2 * math.pi, 2 * math.pi, "rad", "a phase"),
    "pause_time": (0.0, MAX_WALK_TIME, "s", "within the longest walk, MAX_WALK_TIME"),
    "pause_duration": (0.0, MAX_WALK_TIME, "s", "within the longest walk, MAX_WALK_TIME"),
    "pause_ramp": (0.3, 5.0, "s", "sampled 0.4 .. 0.8; 0.3 s brakes 1 m/s at a peak 5 m/s^2"),
    "wander_amplitude": (0.0, 1.5, "m",
                         "sampled 0 .. 0.9 (OOD_RANGES), with a wide margin"),
    "wander_wavelength": (0.5, 10.0, "m",
                          "sampled 1.0 .. 4.5; not shorter than a step"),
    "wander_phase": (-2 * math.pi, 2 * math.pi, "rad", "a phase"),
    "wander_loop": (0.0, 1.0, "", "0: a lateral meander .. 1: loops"),
    "wander_fade_x": (-WALK_HALF_SIZE, WALK_HALF_SIZE, "m", "on the floor (WALK_HALF_SIZE)"),
}




def check_field(name: str, value: object) -> float:
    """``value`` as a float if it is a valid ``WalkerParams.<name>`` (see :data:`FIELD_RANGES`).

    Raises:
        ValueError: not a real number (bools are not), not finite, or outside the field's range;
            the message names the field and the range.
    """
    lo, hi, unit, why = FIELD_RANGES[name]
    return checked_number(f"walker {name}", value, lo, hi, unit, why)


def check_overrides(overrides: object) -> dict[str, object]:
    """Validate walker overrides (reset's ``options["walker"]``) field by field, as a dict.

    ``kind`` is not an override: the env's ``receiver`` option chooses ID or OOD.

    Raises:
        ValueError: not a mapping, a key that is not a WalkerParams field, or a bad value.
    """
    if not isinstance(overrides, Mapping):
        raise ValueError(
            "walker overrides must be a dict of WalkerParams fields, got "
            f"{type(overrides).__name__}"
        )
    known = {f.name for f in fields(WalkerParams)} - {"kind"}
    bad = [k for k in overrides if not isinstance(k, str)]
    if bad:
        raise ValueError(f"walker override names must be strings, got {bad!r}")
    if "kind" in overrides:
        raise ValueError(
            "walker 'kind' is not an override: choose the walker with the receiver option "
            f"('id' or 'ood'), got walker kind {overrides['kind']!r}"
        )
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise ValueError(f"unknown WalkerParams field(s) {unknown}; known: {sorted(known)}")
    out = dict(overrides)
    for name, value in out.items():
        if name == "ood_mode":
            if value is not None and value not in OOD_MODES:
                raise ValueError(f"walker ood_mode must be None or one of {OOD_MODES}, "
                                 f"got {value!r}")
        elif name == "start_xy":
            _start_xy(value)
        else:
            check_field(name, value)
    return out


def _start_xy(value: object) -> tuple[float, float]:
    """A valid start point (two numbers on the floor, see :data:`WALK_HALF_SIZE`)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list, np.ndarray)):
        raise ValueError(f"walker start_xy must be a pair of numbers, got {value!r}")
    items = list(value)
    if len(items) != 2 or not all(is_real_number(v) for v in items):
        raise ValueError(f"walker start_xy must be a pair of numbers, got {value!r}")
    start = (float(items[0]), float(items[1]))
    if not all(math.isfinite(v) and abs(v) <= WALK_HALF_SIZE for v in start):
        raise ValueError(
            f"walker start_xy must lie in [{-WALK_HALF_SIZE:g}, {WALK_HALF_SIZE:g}] m in x and y "
            f"(on the floor), got {value!r}"
        )
    return start


def _quantile_sample(
    u: np.ndarray | float, table: tuple[tuple[float, ...], tuple[float, ...]]
) -> np.ndarray:
    """Map uniforms ``u`` in [0, 1] through a piecewise-linear quantile function."""
    probs, values = table
    return np.interp(u, probs, values)


_erf = np.vectorize(math.erf, otypes=[np.float64])


@dataclass(frozen=True)
class WalkerParams:
    """One receiver: where they start, how fast they walk, how tall they are and how they deviate.

    Args:
        kind: ``"id"`` (walks straight past) or ``"ood"`` (wanders or pauses, paper Sec. V-A).
        start_xy: pelvis xy at t = 0, m.
        speed: nominal walking speed, m/s (data: per-recording median 0.57 .. 1.13, median 0.83).
        pass_y: y of the line along which the receiver passes the giver, m.
        end_x: x where the walk ends, m (data: about -0.8).
        height: body height, m; shoulder and hand heights scale with it.
        ood_mode: None for ID; ``"wander"`` or ``"pause"`` for OOD.
        approach_x: x by which the path has converged from ``start_y`` onto ``pass_y``.
        start_turn: initial walking direction relative to the straight line toward
            ``(approach_x, pass_y)``, rad; positive turns toward +y (the giver's side).
        start_bulge: how long the walker keeps its initial direction (Hermite tangent length
            at the start over the straight-line distance; larger = wider curve).
        step_length_ratio: step length / height; cadence = speed / step length (~1.7 steps/s).
        sway_amplitude: lateral pelvis sway, m, one period per stride.
        speed_ripple: relative speed oscillation at the step frequency.
        drift_amplitude: relative slow speed variation over the walk.
        drift_frequency: frequency of that slow variation, Hz.
        drift_phase: its phase, rad.
        gait_phase: stride phase at t = 0, rad.
        pause_time: OOD "pause": seconds after the start at which the receiver begins to stop.
        pause_duration: OOD "pause": seconds standing still.
        pause_ramp: OOD "pause": seconds to decelerate to rest (and to accelerate again).
        wander_amplitude: OOD (either mode; 0: none): lateral meander amplitude, m.
        wander_wavelength: OOD: meander wavelength along the path, m.
        wander_phase: OOD: meander phase, rad.
        wander_loop: OOD: how much the meander also runs along x (0: purely lateral;
            near 1 with a large amplitude the path makes loops, as some recordings do).
        wander_fade_x: OOD: the meander fades out over the 0.6 m of x before this x
            so the receiver is back on the passing line for the handover.
    """

    kind: str
    start_xy: tuple[float, float]
    speed: float
    pass_y: float
    end_x: float = -0.8
    height: float = DEFAULT_HEIGHT
    ood_mode: str | None = None
    approach_x: float = 0.3
    start_turn: float = 0.0
    start_bulge: float = 1.0
    step_length_ratio: float = 0.28
    sway_amplitude: float = 0.012
    speed_ripple: float = 0.05
    drift_amplitude: float = 0.05
    drift_frequency: float = 0.25
    drift_phase: float = 0.0
    gait_phase: float = 0.0
    pause_time: float = 1.5
    pause_duration: float = 1.5
    pause_ramp: float = 0.6
    wander_amplitude: float = 0.3
    wander_wavelength: float = 1.5
    wander_phase: float = 0.0
    wander_loop: float = 0.5
    wander_fade_x: float = 0.2

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")
        if self.kind == "id" and self.ood_mode is not None:
            raise ValueError(f"an ID walker has ood_mode=None, got {self.ood_mode!r}")
        if self.kind == "ood" and (
            not isinstance(self.ood_mode, str) or self.ood_mode not in OOD_MODES
        ):
            raise ValueError(f"an OOD walker needs ood_mode in {OOD_MODES}, got {self.ood_mode!r}")
        start = _start_xy(self.start_xy)
        object.__setattr__(self, "start_xy", start)
        for name in FIELD_RANGES:
            object.__setattr__(self, name, check_field(name, getattr(self, name)))
        if start[0] <= self.end_x + 0.1:
            raise ValueError(
                f"start x ({start[0]:.3f}) must be ahead of end_x ({self.end_x:.3f}) by > 0.1 m"
            )
        if self.speed_ripple + self.drift_amplitude >= 0.9:
            raise ValueError(
                "speed_ripple + drift_amplitude must be < 0.9 (the walker never stops by itself), "
                f"got {self.speed_ripple} + {self.drift_amplitude}"
            )

    @property
    def step_length(self) -> float:
        """Length of one step, m."""
        return self.step_length_ratio * self.height

    @property
    def is_ood(self) -> bool:
        """True for an out-of-distribution walker."""
        return self.kind == "ood"


def sample_walker(rng: np.random.Generator, kind: str = "id", **overrides: object) -> WalkerParams:
    """Draw a walker from the seeded distributions calibrated to the public data.

    The same number of random draws is made whatever the kind and overrides, so fixing one field
    (e.g. ``speed=1.0``) leaves all the others as they would have been.

    Args:
        rng: the random generator (the env passes ``self.np_random``).
        kind: ``"id"`` or ``"ood"``.
        **overrides: fields of :class:`WalkerParams` to fix, e.g. ``height=1.8, speed=1.0``.

    Raises:
        ValueError: unknown kind, an invalid override (:func:`check_overrides`) or an invalid
            resulting walker.
    """
    if not isinstance(kind, str) or kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    overrides = check_overrides(overrides)
    # Start point: Gaussian copula of (bearing, distance) with the data's rank correlation,
    # restricted to the region where recordings start (a fixed number of candidates, so the
    # number of draws does not depend on the outcome).
    z = rng.standard_normal((_START_CANDIDATES, 2))
    rho = START_RANK_CORRELATION
    z2 = rho * z[:, 0] + math.sqrt(1.0 - rho * rho) * z[:, 1]
    u_bearing = 0.5 * (1.0 + _erf(z[:, 0] / math.sqrt(2.0)))
    u_dist = 0.5 * (1.0 + _erf(z2 / math.sqrt(2.0)))
    bearing = np.radians(_quantile_sample(u_bearing, START_BEARING_DEG_Q))
    distance = _quantile_sample(u_dist, START_DISTANCE_Q)
    cand = np.stack([distance * np.cos(bearing), distance * np.sin(bearing)], axis=-1)
    (xlo, xhi), (ylo, yhi) = START_BOX
    inside = (cand[:, 0] >= xlo) & (cand[:, 0] <= xhi) & (cand[:, 1] >= ylo) & (cand[:, 1] <= yhi)
    pick = int(np.argmax(inside)) if inside.any() else 0
    start = np.clip(cand[pick], (xlo, ylo), (xhi, yhi))
    u = rng.random(8)
    g = rng.random(13)
    mode_draw = rng.random()
    params: dict[str, object] = {
        "kind": kind,
        "start_xy": (float(start[0]), float(start[1])),
        "speed": float(_quantile_sample(u[0], SPEED_Q)),
        "pass_y": float(_quantile_sample(u[1], PASS_Y_Q)),
        "end_x": END_X_RANGE[0] + (END_X_RANGE[1] - END_X_RANGE[0]) * float(u[2]),
        "height": float(_quantile_sample(u[3], HEIGHT_Q)),
        "ood_mode": None if kind == "id" else OOD_MODES[int(mode_draw < 0.5)],
        "approach_x": 0.1 + 0.4 * float(u[4]),
        "step_length_ratio": 0.26 + 0.04 * float(u[5]),
        "sway_amplitude": 0.006 + 0.014 * float(u[6]),
        "speed_ripple": 0.03 + 0.04 * float(u[7]),
        "drift_amplitude": 0.08 * float(g[0]),
        "drift_frequency": 0.15 + 0.2 * float(g[1]),
        "drift_phase": 2.0 * math.pi * float(g[2]),
        "gait_phase": 2.0 * math.pi * float(g[3]),
        "pause_time": 0.8 + 1.4 * float(g[4]),
        "pause_duration": 0.8 + 1.7 * float(g[5]),
        "pause_ramp": 0.4 + 0.4 * float(g[6]),
        "wander_amplitude": 0.15 + 0.3 * float(g[7]),
        "wander_wavelength": 1.0 + 1.2 * float(g[8]),
        "wander_phase": 2.0 * math.pi * float(g[9]),
        "wander_loop": float(g[10]),
        "start_bulge": 1.0 + 0.6 * float(g[12]),
        "start_turn": math.radians(float(_quantile_sample(g[11], START_TURN_DEG_Q))),
    }
    if kind == "ood":
        params.update(_ood_fields(str(params["ood_mode"]), g))
    params.update(overrides)
    return WalkerParams(**params)  # type: ignore[arg-type]


def _ood_fields(mode: str, g: np.ndarray) -> dict[str, float]:
    """An OOD walker's calibrated fields (:data:`OOD_RANGES`) from the sampler's uniforms ``g``
    (:data:`OOD_UNIFORM`): no extra draw, so an ID walker and everything drawn after it stay as
    they were."""
    out = {}
    for name, (lo, hi) in OOD_RANGES[mode].items():
        u = float(g[OOD_UNIFORM[name]])
        if name in OOD_SYMMETRIC:  # magnitude uniform in [lo, hi], either sign
            out[name] = math.copysign(lo + (hi - lo) * ((2.0 * u) % 1.0), 0.5 - u)
        else:
            out[name] = lo + (hi - lo) * u
    return out
