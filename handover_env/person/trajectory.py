"""A walker's walk: the pelvis track from start to end, and the shoulder and hand along it.

:func:`base_trajectory` turns a :class:`handover_env.person.motion.WalkerParams` into the pelvis
track at a fixed rate (a smooth path onto the passing line, speed drift and ripple, OOD pauses
and meanders, gait sway); :func:`shoulder_position` and :func:`hand_position` place the right
shoulder and hand on a body of a given height (proportions from
:mod:`handover_env.person.motion`). Deterministic and pure numpy: the synthetic dataset
(:mod:`handover_env.person.synthetic`) and the env's scripted receivers
(:mod:`handover_env.person.person`) share them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from handover_env.person.motion import (
    ARM_REACH_RATIO,
    HAND_REST_HEIGHT_RATIO,
    HAND_REST_LATERAL_RATIO,
    HAND_SWING_RATIO,
    MAX_WALK_TIME,
    PELVIS_LIMIT,
    SHOULDER_HALF_WIDTH_RATIO,
    SHOULDER_HEIGHT_RATIO,
    WalkerParams,
)

WANDER_SMOOTHING = 0.15  # m, Gaussian smoothing of a wandering path (rounds off cusps)
WANDER_FADE_LENGTH = 0.6  # m of x over which an OOD meander fades out before wander_fade_x
MAX_TURN_RATE = 3.0  # rad/s: walkers slow down in tight curves and turn no faster than this
FREE_CURVATURE = 1.5  # 1/m: curves gentler than this (radius > 0.67 m) are walked at full speed


def _smoothstep(x: np.ndarray) -> np.ndarray:
    """C1 ramp from 0 (x <= 0) to 1 (x >= 1)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


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
    then the straight passing line to ``end_x``. An OOD walker (either mode) adds a trochoid-like
    offset (a lateral meander, with loops when ``wander_loop`` is large) that starts at zero and
    fades out before the handover.
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
    if params.ood_mode is not None and params.wander_amplitude > 0:
        fade_start = params.wander_fade_x + WANDER_FADE_LENGTH
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
        # Fade by where the meander takes the walker too (a loop swings back along x): no part of
        # it comes nearer the giver than wander_fade_x.
        moved = xy + envelope[:, None] * offset
        envelope = envelope * _smoothstep(
            (moved[:, 0] - params.wander_fade_x) / WANDER_FADE_LENGTH
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
