"""How a person walks past the giver and reaches for the object: one model for the data and the env.

The paper's receiver (Sec. IV-A, "Data Collection"; Sec. V-A) walks toward the giver, passes at
their side and takes the object on the move. The same functions here drive

* the synthetic dataset (:mod:`handover_env.data.synthetic`), and
* the env's scripted ID/OOD receivers (:mod:`handover_env.person.receiver`),

so the simulated people and the demonstrations cannot drift apart.

Frame (the public dataset's): z up, floor at z = 0, giver/robot near the origin facing +x. The
receiver starts about 2.5 m away on the giver's right-front, walks toward -x, passes the giver's
side along ``y = pass_y`` (about -0.6 .. -1.2) and stops being recorded near ``x = -0.8``. While
walking toward -x (heading yaw ~ pi) the receiver's RIGHT side, and right hand, face +y: the giver.

All randomness lives in :func:`sample_walker`; :func:`base_trajectory` and the body functions are
deterministic and pure numpy, so a seeded ``np.random.Generator`` reproduces a walker exactly.

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
WANDER_SMOOTHING = 0.15  # m, Gaussian smoothing of a wandering path (rounds off cusps)
MAX_TURN_RATE = 3.0  # rad/s: walkers slow down in tight curves and turn no faster than this
FREE_CURVATURE = 1.5  # 1/m: curves gentler than this (radius > 0.67 m) are walked at full speed

KINDS = ("id", "ood")
OOD_MODES = ("wander", "pause")

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
    "start_bulge": (0.25, 3.0, "",
                    "sampled 1.0 .. 1.6; longer start tangents swing the path far out"),
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
    "wander_amplitude": (0.0, 0.6, "m", "sampled 0.15 .. 0.45"),
    "wander_wavelength": (0.5, 10.0, "m", "sampled 1.0 .. 2.2; not shorter than a step"),
    "wander_phase": (-2 * math.pi, 2 * math.pi, "rad", "a phase"),
    "wander_loop": (0.0, 1.0, "", "0: a lateral meander .. 1: loops"),
    "wander_fade_x": (-WALK_HALF_SIZE, WALK_HALF_SIZE, "m", "on the floor (WALK_HALF_SIZE)"),
}


def _is_number(value: object) -> bool:
    """A real number: int, float or a numpy one, and not a bool."""
    return not isinstance(value, (bool, np.bool_)) and isinstance(
        value, (int, float, np.integer, np.floating)
    )


def check_field(name: str, value: object) -> float:
    """``value`` as a float if it is a valid ``WalkerParams.<name>`` (see :data:`FIELD_RANGES`).

    Raises:
        ValueError: not a real number (bools are not), not finite, or outside the field's range;
            the message names the field and the range.
    """
    lo, hi, unit, why = FIELD_RANGES[name]
    if not _is_number(value):
        raise ValueError(f"walker {name} must be a number, got {value!r}")
    x = float(value)  # type: ignore[arg-type]
    if not (math.isfinite(x) and lo <= x <= hi):
        raise ValueError(
            f"walker {name} must be {'' if math.isfinite(x) else 'finite and '}in [{lo:g}, "
            f"{hi:g}]{' ' + unit if unit else ''} ({why}), got {value!r}"
        )
    return x


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
    if len(items) != 2 or not all(_is_number(v) for v in items):
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


def _smoothstep(x: np.ndarray) -> np.ndarray:
    """C1 ramp from 0 (x <= 0) to 1 (x >= 1)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


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
        wander_amplitude: OOD "wander": lateral meander amplitude, m.
        wander_wavelength: OOD "wander": meander wavelength along x, m.
        wander_phase: OOD "wander": meander phase, rad.
        wander_loop: OOD "wander": how much the meander also runs along x (0: purely lateral;
            near 1 with a large amplitude the path makes loops, as some recordings do).
        wander_fade_x: OOD "wander": the meander fades out between ``approach_x + 0.6`` and this x
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
    params.update(overrides)
    return WalkerParams(**params)  # type: ignore[arg-type]


@dataclass(frozen=True)
class BaseTrajectory:
    """The receiver's pelvis track at a fixed rate.

    Attributes:
        t: (T,) seconds from 0.
        xy: (T, 2) pelvis xy, m.
        heading: (T,) walking-direction yaw, rad (pi = toward -x); smooth, from the path's
            tangent, so it is defined even while standing still.
        gait_phase: (T,) stride phase, rad: advances by 2 pi per stride (two steps) with the
            distance walked and freezes while paused; feeds :func:`hand_position`'s arm swing.
    """

    t: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    gait_phase: np.ndarray

    def __post_init__(self) -> None:
        n = self.t.shape[0]
        if self.xy.shape != (n, 2) or self.heading.shape != (n,) or self.gait_phase.shape != (n,):
            raise ValueError("BaseTrajectory arrays must share their length T")

    def __len__(self) -> int:
        return int(self.t.shape[0])


def _path(params: WalkerParams, n: int = 1201) -> tuple[np.ndarray, np.ndarray]:
    """Dense path from start to end as (xy (m, 2), cumulative arc length (m,)).

    A cubic Hermite curve from the start to the convergence point ``(x_conv, pass_y)``, leaving
    the start ``start_turn`` away from the straight line to that point and arriving along -x,
    then the straight passing line to ``end_x``. OOD "wander" adds a trochoid-like offset (lateral
    meander, with loops when ``wander_loop`` is large) that starts at zero and fades out before
    the handover.
    """
    x0, y0 = params.start_xy
    x_conv = max(min(params.approach_x, x0 - 1.0), params.end_x + 0.05)
    p0, p1 = np.array([x0, y0]), np.array([x_conv, params.pass_y])
    chord = p1 - p0
    length = float(np.linalg.norm(chord))
    c, s = math.cos(-params.start_turn), math.sin(-params.start_turn)
    d0 = np.array([c * chord[0] - s * chord[1], s * chord[0] + c * chord[1]])  # clockwise = +y side
    m0, m1 = params.start_bulge * d0, np.array([-length, 0.0])
    n_curve = max(int(n * (x0 - x_conv) / (x0 - params.end_x)), 50)
    u = np.linspace(0.0, 1.0, n_curve)[:, None]
    h00, h10, h01, h11 = (
        2 * u**3 - 3 * u**2 + 1,
        u**3 - 2 * u**2 + u,
        -2 * u**3 + 3 * u**2,
        u**3 - u**2,
    )
    curve = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
    line_x = np.linspace(x_conv, params.end_x, max(n - n_curve, 10))[1:]
    line = np.stack([line_x, np.full_like(line_x, params.pass_y)], axis=-1)
    xy = np.concatenate([curve, line])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    if params.ood_mode == "wander":
        fade_start = max(params.wander_fade_x + 0.6, x0 - 0.5)
        taper = _smoothstep(
            (xy[:, 0] - params.wander_fade_x) / max(fade_start - params.wander_fade_x, 1e-6)
        )
        envelope = params.wander_amplitude * taper * _smoothstep(arc / 0.4)
        theta = 2 * math.pi * arc / params.wander_wavelength + params.wander_phase
        phi = params.wander_phase
        offset = np.stack(
            [params.wander_loop * (np.cos(theta) - math.cos(phi)), np.sin(theta) - math.sin(phi)],
            axis=-1,
        )
        xy = _smooth_polyline(xy + envelope[:, None] * offset, WANDER_SMOOTHING)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    return xy, arc


def _smooth_polyline(xy: np.ndarray, sigma: float) -> np.ndarray:
    """Resample a polyline evenly along its length and Gaussian-smooth it (sigma in metres).

    Rounds off the cusps a looping meander can have, so the walking direction turns at human
    rates; the end points stay where they were.
    """
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    step = sigma / 8.0
    grid = np.linspace(0.0, arc[-1], max(int(arc[-1] / step), 2) + 1)
    even = np.stack([np.interp(grid, arc, xy[:, 0]), np.interp(grid, arc, xy[:, 1])], axis=-1)
    half = int(4 * sigma / step)
    kernel = np.exp(-0.5 * (np.arange(-half, half + 1) * step / sigma) ** 2)
    kernel /= kernel.sum()
    # Reflect through the end points (odd extension) so that they and the end directions stay put.
    head = 2 * even[0] - even[half:0:-1]
    tail = 2 * even[-1] - even[-2 : -half - 2 : -1]
    padded = np.concatenate([head, even, tail])
    return np.stack([np.convolve(padded[:, j], kernel, mode="valid") for j in range(2)], axis=-1)


def _pause_factor(params: WalkerParams, t: np.ndarray) -> np.ndarray:
    """Multiplier on speed: 1 normally, 0 while paused, C1 ramps in between (OOD "pause")."""
    if params.ood_mode != "pause":
        return np.ones_like(t)
    t0, ramp, hold = params.pause_time, params.pause_ramp, params.pause_duration
    return 1.0 - _smoothstep((t - t0) / ramp) + _smoothstep((t - (t0 + ramp + hold)) / ramp)


def _turn_budget(
    path_xy: np.ndarray, arc: np.ndarray, turn_length: float
) -> tuple[np.ndarray, ...]:
    """Knots mapping walking progress u to distance s and heading along a polyline.

    Sharp turning costs progress: at each vertex the walker spends ``turn_length`` x (turn angle
    beyond what :data:`FREE_CURVATURE` allows) of progress turning before going on. With progress
    advancing at the walking speed v and ``turn_length = v / MAX_TURN_RATE``, the speed along a
    curve of curvature k > k_free becomes v / (1 + v (k - k_free) / MAX_TURN_RATE), so the yaw
    rate stays below max(MAX_TURN_RATE, v k_free), gentle curves are not slowed at all, and a
    sharp kink is turned through on the spot.

    Returns:
        ``(s_knots, u_knots, heading_knots)``; headings are relative to -x (add pi for the yaw).
    """
    seg = np.diff(arc)
    theta = np.unwrap(np.arctan2(-np.diff(path_xy[:, 1]), -np.diff(path_xy[:, 0])))
    free = FREE_CURVATURE * 0.5 * (seg[1:] + seg[:-1])  # turning that costs nothing
    turn = turn_length * np.maximum(np.abs(np.diff(theta)) - free, 0.0)
    m = seg.size
    steps = np.empty(2 * m - 1)
    steps[0::2], steps[1::2] = seg, turn
    u_knots = np.concatenate([[0.0], np.cumsum(steps + 1e-12)])
    s_knots = np.concatenate([[0.0], np.repeat(arc[1:-1], 2), [arc[-1]]])
    heading_knots = np.repeat(theta, 2)
    return s_knots, u_knots, heading_knots


def base_trajectory(params: WalkerParams, rate_hz: float = 30.0) -> BaseTrajectory:
    """The full walk from ``start_xy`` to ``end_x``, sampled at ``rate_hz``.

    Deterministic given ``params``. The pelvis moves along a smooth path that converges from the
    start onto the passing line ``y = pass_y`` (OOD "wander" adds a lateral meander), at a speed
    that carries a slow drift, a ripple at the step frequency and, for OOD "pause", a stop and
    restart; a lateral gait sway of one period per stride is added on top.

    Args:
        params: the walker.
        rate_hz: sampling rate (the dataset and the env's camera use 30 Hz).

    Returns:
        The trajectory; its last sample is the first at which the pelvis reaches ``end_x``.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be positive and finite, got {rate_hz}")
    path_xy, arc = _path(params)
    s_knots, u_knots, heading_knots = _turn_budget(path_xy, arc, params.speed / MAX_TURN_RATE)
    total = float(u_knots[-1])
    dt = 1.0 / rate_hz
    pause_total = (
        (params.pause_duration + 2 * params.pause_ramp) if params.ood_mode == "pause" else 0.0
    )
    slowest = params.speed * (1.0 - params.speed_ripple - params.drift_amplitude)
    pausing = params.pause_time + pause_total if params.ood_mode == "pause" else 0.0
    if pausing + total / slowest > MAX_WALK_TIME:
        raise ValueError(
            f"the walk would take up to {pausing + total / slowest:.0f} s ({total:.1f} m of "
            "path at down to "
            f"{slowest:.2f} m/s, pauses included), more than MAX_WALK_TIME = {MAX_WALK_TIME:g} s: "
            "walk faster (speed, speed_ripple, drift_amplitude), shorter (start_xy, end_x) or "
            "pause less (pause_time, pause_duration)"
        )
    t = (
        np.arange(
            math.ceil((params.pause_time + pause_total + total / slowest + 1.0) * rate_hz) + 2
        )
        * dt
    )
    slow = 1.0 + params.drift_amplitude * np.sin(
        2 * math.pi * params.drift_frequency * t + params.drift_phase
    )
    base_v = params.speed * slow * _pause_factor(params, t)

    def integrate(v: np.ndarray) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])

    # Progress u along the path (distance plus turning budget). The step-frequency ripple needs
    # the distance walked; one fixed-point pass is accurate to well under a millimetre.
    u = integrate(base_v)
    step_phase = (
        2 * math.pi * np.interp(u, u_knots, s_knots) / params.step_length + params.gait_phase
    )
    u = integrate(base_v * (1.0 + params.speed_ripple * np.sin(2 * step_phase)))
    n = min(max(int(np.searchsorted(u, total)) + 1, 2), t.size)
    t, u = t[:n], np.minimum(u[:n], total)
    s = np.interp(u, u_knots, s_knots)
    xy = np.stack([np.interp(s, arc, path_xy[:, 0]), np.interp(s, arc, path_xy[:, 1])], axis=-1)
    heading = math.pi + np.interp(u, u_knots, heading_knots)
    gait = 2 * math.pi * s / (2 * params.step_length) + params.gait_phase
    # Lateral sway: one period per stride, vanishing while standing.
    moving = np.clip(np.gradient(s, dt) / params.speed, 0.0, 1.0)
    sway = params.sway_amplitude * np.sin(gait) * moving
    right = np.stack([np.sin(heading), -np.cos(heading)], axis=-1)
    xy = xy + sway[:, None] * right
    if np.abs(xy).max() > PELVIS_LIMIT:
        raise ValueError(
            f"the walk leaves the floor: the pelvis reaches {np.abs(xy).max():.2f} m from the "
            f"giver in x or y, beyond PELVIS_LIMIT = {PELVIS_LIMIT:g} m (start_xy, start_turn, "
            "start_bulge, pass_y, end_x and the wander settings shape the path)"
        )
    return BaseTrajectory(t=t, xy=xy, heading=heading, gait_phase=np.mod(gait, 2 * math.pi))


def arm_reach(height: float) -> float:
    """Max distance from the right shoulder to the grip centre of the right hand, m."""
    return ARM_REACH_RATIO * float(height)


def _frame(heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit forward and right vectors (..., 2) for a walking yaw."""
    c, s = np.cos(heading), np.sin(heading)
    return np.stack([c, s], axis=-1), np.stack([s, -c], axis=-1)


def shoulder_position(
    base_xy: np.ndarray, heading: np.ndarray | float, height: np.ndarray | float
) -> np.ndarray:
    """Right shoulder xyz (..., 3) for pelvis xy (..., 2), yaw (...) and body height (scalar or
    (...))."""
    base_xy = np.asarray(base_xy, dtype=np.float64)
    heading = np.asarray(heading, dtype=np.float64)
    height = np.asarray(height, dtype=np.float64)
    _, right = _frame(heading)
    xy = base_xy + (SHOULDER_HALF_WIDTH_RATIO * height)[..., None] * right
    z = np.broadcast_to(SHOULDER_HEIGHT_RATIO * height, xy.shape[:-1])
    return np.concatenate([xy, z[..., None]], axis=-1)


def hand_position(
    base_xy: np.ndarray,
    heading: np.ndarray | float,
    height: np.ndarray | float,
    target_xyz: np.ndarray | None = None,
    reach: np.ndarray | float = 0.0,
    swing_phase: np.ndarray | float | None = None,
) -> np.ndarray:
    """Right hand xyz (..., 3), vectorised over leading dimensions.

    With ``reach = 0`` the hand hangs beside the hip and swings forward and back once per stride
    (a pendulum, so it also rises a little at the ends of the swing). As ``reach`` goes to 1 it
    moves in a straight line toward ``target_xyz``; the result is always kept within
    :func:`arm_reach` of the shoulder, so an out-of-reach target is approached but not reached.

    Args:
        base_xy: (..., 2) pelvis xy.
        heading: (...) walking yaw, rad.
        height: body height, m (scalar or (...)).
        target_xyz: (..., 3) what the hand reaches for (the object); required when reach > 0.
        reach: (...) fraction of the way from the rest pose to the target, clipped to [0, 1].
        swing_phase: (...) stride phase (``BaseTrajectory.gait_phase``); by default derived from
            the distance walked along -x, which is what the env has online.

    Raises:
        ValueError: ``reach > 0`` without a target.
    """
    base_xy = np.asarray(base_xy, dtype=np.float64)
    heading = np.asarray(heading, dtype=np.float64)
    h = np.asarray(height, dtype=np.float64)
    forward, right = _frame(heading)
    if swing_phase is None:
        swing_phase = 2 * math.pi * (-base_xy[..., 0]) / (2 * 0.28 * h)
    swing = HAND_SWING_RATIO * h * np.sin(np.asarray(swing_phase, dtype=np.float64))
    arm = HAND_REST_HEIGHT_RATIO * h
    rest_xy = (
        base_xy + (HAND_REST_LATERAL_RATIO * h)[..., None] * right + swing[..., None] * forward
    )
    rest_z = arm + swing**2 / (2.0 * (SHOULDER_HEIGHT_RATIO - HAND_REST_HEIGHT_RATIO) * h)
    rest = np.concatenate(
        [rest_xy, np.broadcast_to(rest_z, rest_xy.shape[:-1])[..., None]], axis=-1
    )
    r = np.clip(np.asarray(reach, dtype=np.float64), 0.0, 1.0)
    if target_xyz is None:
        if np.any(r > 0):
            raise ValueError("hand_position: reach > 0 needs a target_xyz")
        return rest
    target = np.asarray(target_xyz, dtype=np.float64)
    hand = rest + r[..., None] * (target - rest)
    shoulder = shoulder_position(base_xy, heading, h)
    offset = hand - shoulder
    dist = np.linalg.norm(offset, axis=-1, keepdims=True)
    limit = ARM_REACH_RATIO * np.broadcast_to(h, dist.shape[:-1])[..., None]
    scale = np.where(dist > limit, limit / np.maximum(dist, 1e-12), 1.0)
    return shoulder + offset * scale
