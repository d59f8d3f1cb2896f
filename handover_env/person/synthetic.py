"""Synthetic handover demonstrations: the embedded default dataset for demos and tests.

Each episode is a receiver walking past a giver who hands over an object (paper Sec. IV-A,
"Data Collection", and Sec. V-A), sampled at 30 Hz like the public recordings:

1. **Receiver walk.** A walker from :func:`handover_env.person.motion.sample_walker` (ID, or OOD
   wandering/pausing) and its :func:`~handover_env.person.trajectory.base_trajectory`: gait sway,
   speed ripple and drift. This is the same model the env's scripted receivers use.
2. **Giver reach.** The giver stands near the origin holding the object at a rest point in front
   of them. When the receiver comes within a trigger distance (after a reaction time) the giver
   extends the arm toward where the receiver's hand will be: a meeting point ahead and to the
   right of the receiver's pelvis, limited to the giver's reach around their pelvis. The hand
   lifts a little and comes down to the handover height as the moment approaches, and then moves
   along with the receiver (velocity matching, the "dynamic" handover).
3. **Receiver reach and pull.** The receiver's right hand
   (:func:`~handover_env.person.trajectory.hand_position`) reaches for the object over a reach
   time and meets it when the pelvis passes a sampled take point; this is the transfer (the hand
   is nearest the object there, the definition used by :mod:`handover_env.data.stats`). Then the
   receiver holds the object, pulls it toward the body and carries it on.
4. **Object orientation** turns about z with the giver's arm sweep (as in the recordings).
5. **Mocap-like noise**: white plus slowly varying (AR(1)) errors, larger for the body-tracked
   pelvis and hand (ZED) than for the motion-captured object (OptiTrack).

Calibration. Every distribution below is a piecewise-linear quantile function built from summary
STATISTICS of the public dataset's 875-recording development copy (quantiles over recordings of:
the pelvis x at the transfer, the object's position relative to the receiver pelvis and to the
giver at the transfer, the transfer height, the object's peak height before it, the receiver's
distance from the object when the giver starts to move, the hand-object distance at the
transfer, the object's start point). No trajectory or per-recording value is copied.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter
from tqdm.auto import tqdm

from handover_env.data.dataset import DEFAULT_RATE_HZ, Episode, HandoverDataset
from handover_env.person import motion as rm
from handover_env.person import trajectory

_P = (0.0, 0.01, 0.05, 0.25, 0.50, 0.75, 0.95, 0.99, 1.0)
#: Receiver pelvis x at the transfer (m), ID and OOD recordings.
TAKE_X_Q = {
    "id": (_P, (-0.80, -0.798, -0.79, -0.598, -0.284, 0.059, 0.93, 1.154, 1.355)),
    "ood": (_P, (-0.80, -0.798, -0.793, -0.652, -0.205, 0.144, 0.84, 1.205, 1.23)),
}
#: Object relative to the receiver pelvis at the transfer: ahead along the walk and to the right
#: (m).
MEET_FORWARD_Q = (_P, (0.0, 0.034, 0.116, 0.182, 0.221, 0.254, 0.33, 0.396, 0.45))
MEET_RIGHT_Q = (_P, (0.06, 0.111, 0.155, 0.223, 0.268, 0.313, 0.404, 0.531, 0.60))
#: Object height at the transfer (m) and its peak height before the transfer (m).
MEET_HEIGHT_Q = (_P, (0.80, 0.835, 1.048, 1.197, 1.268, 1.322, 1.361, 1.379, 1.40))
PEAK_HEIGHT_Q = (_P, (1.285, 1.31, 1.323, 1.346, 1.358, 1.371, 1.393, 1.411, 1.44))
#: Horizontal distance of the object from the giver's pelvis at the transfer (m): the giver's reach.
GIVER_REACH_Q = (_P, (0.57, 0.653, 0.703, 0.77, 0.859, 0.945, 1.085, 1.156, 1.25))
#: Distance of the receiver pelvis from the object's start when the giver starts to move (m).
TRIGGER_DISTANCE_Q = (_P, (0.75, 1.058, 1.187, 1.416, 1.56, 1.70, 1.891, 2.028, 2.2))
#: Hand-object distance at the transfer (m): where the tracked hand joint sits on the object.
CONTACT_DISTANCE_Q = (_P, (0.006, 0.02, 0.04, 0.065, 0.084, 0.103, 0.163, 0.25, 0.30))
#: Object start point (median) and spread (std) in the recordings, m; giver pelvis xy (median), m.
OBJECT_HOME = (0.493, -0.309, 1.26)
OBJECT_HOME_STD = (0.008, 0.004, 0.002)
GIVER_PELVIS_XY = (-0.08, 0.03)
#: Extra reach of the giver beyond the distance observed at the transfer: the giver's hand is
#: not always at full stretch when the receiver takes the object.
GIVER_REACH_MARGIN = 0.15
_SMOOTHSTEP_AT_3CM = 0.14  # smoothstep(0.14) ~ 0.055 ~ 3 cm of a ~0.55 m extension
#: Real recordings last 69 .. 287 frames; walks outside that range are redrawn.
LENGTH_RANGE = (69, 287)


@dataclass(frozen=True)
class NoiseModel:
    """Mocap-like measurement noise: white (std) plus AR(1) drift (std, correlation per frame).

    Args:
        pelvis_white: ZED pelvis white noise per axis, m.
        pelvis_drift: ZED pelvis slowly varying error per axis, m.
        hand_white: ZED hand white noise per axis, m.
        hand_drift: ZED hand slowly varying error per axis, m.
        object_white: OptiTrack object white noise per axis, m.
        drift_correlation: AR(1) coefficient per frame of the slow errors, in [0, 1).
        quat_white: white noise on each quaternion component before renormalising.
    """

    pelvis_white: float = 0.0007
    pelvis_drift: float = 0.004
    hand_white: float = 0.003
    hand_drift: float = 0.010
    object_white: float = 0.0002
    drift_correlation: float = 0.95
    quat_white: float = 0.0005

    def __post_init__(self) -> None:
        for name in (
            "pelvis_white",
            "pelvis_drift",
            "hand_white",
            "hand_drift",
            "object_white",
            "quat_white",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not 0.0 <= self.drift_correlation < 1.0:
            raise ValueError(f"drift_correlation must be in [0, 1), got {self.drift_correlation}")


def _q(rng: np.random.Generator, table: tuple[tuple[float, ...], tuple[float, ...]]) -> float:
    return float(np.interp(rng.random(), table[0], table[1]))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _ar1(rng: np.random.Generator, n: int, dims: int, std: float, rho: float) -> np.ndarray:
    """Stationary AR(1) noise (n, dims) with marginal std ``std`` and lag-1 correlation ``rho``."""
    if std == 0.0:
        return np.zeros((n, dims))
    eps = rng.standard_normal((n, dims)) * std * math.sqrt(1.0 - rho * rho)
    eps[0] = rng.standard_normal(dims) * std  # start in the stationary distribution
    return lfilter([1.0], [1.0, -rho], eps, axis=0)


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average along axis 0 with edge padding (keeps the length)."""
    if width <= 1:
        return x
    pad = width // 2
    padded = np.pad(x, ((pad, width - 1 - pad), (0, 0)), mode="edge")
    kernel = np.ones(width) / width
    return np.stack(
        [np.convolve(padded[:, j], kernel, mode="valid") for j in range(x.shape[1])], axis=-1
    )


def _yaw_quaternions(yaw: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation by ``yaw`` about z after a small fixed tilt (rx, ry), radians."""
    half = 0.5 * yaw
    qz = np.stack([np.cos(half), np.zeros_like(half), np.zeros_like(half), np.sin(half)], axis=-1)
    angle = float(np.linalg.norm(tilt))
    axis = tilt / angle if angle > 0 else np.array([1.0, 0.0])
    qt = np.array(
        [math.cos(angle / 2), axis[0] * math.sin(angle / 2), axis[1] * math.sin(angle / 2), 0.0]
    )
    w1, x1, y1, z1 = (qz[..., i] for i in range(4))
    w2, x2, y2, z2 = qt
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def synthesize_episode(
    rng: np.random.Generator,
    kind: str = "id",
    source_id: str = "synth",
    rate_hz: float = DEFAULT_RATE_HZ,
    noise: NoiseModel | None = None,
) -> Episode:
    """One synthetic handover (see the module docstring for the model).

    Args:
        rng: the random generator; the episode is a deterministic function of its state.
        kind: ``"id"`` or ``"ood"``.
        source_id: the episode's source id.
        rate_hz: sampling rate.
        noise: measurement noise; ``NoiseModel()`` by default.
    """
    noise = noise if noise is not None else NoiseModel()
    # ---- receiver walk (redrawn until its length is in the recordings' range at 30 Hz)
    lo, hi = (round(v * rate_hz / DEFAULT_RATE_HZ) for v in LENGTH_RANGE)
    for _ in range(100):
        walker = rm.sample_walker(rng, kind)
        traj = trajectory.base_trajectory(walker, rate_hz)
        if lo <= len(traj) <= hi:
            break
    else:  # pragma: no cover - the calibrated distributions make this vanishingly rare
        raise RuntimeError("could not draw a walk of realistic length in 100 tries")
    t, xy, heading, n = traj.t, traj.xy, traj.heading, len(traj)
    forward = np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    right = np.stack([np.sin(heading), -np.cos(heading)], axis=-1)

    # ---- giver and handover parameters
    home = np.asarray(OBJECT_HOME) + rng.standard_normal(3) * np.asarray(OBJECT_HOME_STD)
    giver = np.asarray(GIVER_PELVIS_XY)
    take_x = max(_q(rng, TAKE_X_Q[kind]), walker.end_x)
    meet_fwd, meet_right = _q(rng, MEET_FORWARD_Q), _q(rng, MEET_RIGHT_Q)
    meet_z = _q(rng, MEET_HEIGHT_Q)
    peak_z = max(_q(rng, PEAK_HEIGHT_Q), meet_z)
    giver_reach = _q(rng, GIVER_REACH_Q) + GIVER_REACH_MARGIN
    trigger = _q(rng, TRIGGER_DISTANCE_Q)
    contact = _q(rng, CONTACT_DISTANCE_Q)
    reaction = 0.05 + 0.2 * rng.random()  # s, when the receiver is already within the trigger
    extend_time = 0.8 + 0.7 * rng.random()  # s, giver's arm extension
    descend_time = 0.6 + 0.8 * rng.random()  # s, hand comes down to the handover height
    reach_time = 0.8 + 0.8 * rng.random()  # s, receiver's reach
    pull_time = 0.5 + 0.7 * rng.random()  # s, receiver pulls the object in
    carry_reach = 0.2 + 0.5 * rng.random()  # reach fraction the hand keeps while carrying
    hold_distance = 0.12 + 0.06 * rng.random()  # m, hand joint to object once held
    yaw_gain = 0.3 + 0.4 * rng.random()
    tilt = rng.standard_normal(2) * 0.02

    # ---- timeline: the take (transfer) frame and the giver's onset frame
    crossed = xy[:, 0] <= take_x
    k_take = int(np.argmax(crossed)) if crossed.any() else n - 1
    if 0 < k_take and abs(xy[k_take - 1, 0] - take_x) < abs(xy[k_take, 0] - take_x):
        k_take -= 1  # the frame nearest the take point
    near = np.linalg.norm(xy - home[:2], axis=1) <= trigger
    k_trigger = int(np.argmax(near)) if near.any() else n - 1
    # The trigger statistic is the receiver's distance when the object has moved 3 cm, so the
    # arm starts moving the (smoothstep) time needed for 3 cm of a ~0.5 m extension earlier.
    lead = round(_SMOOTHSTEP_AT_3CM * extend_time * rate_hz)
    k_on = max(k_trigger - lead, round(reaction * rate_hz))
    k_on = int(np.clip(k_on, 1, max(1, k_take - int(0.5 * rate_hz))))
    t_on, t_take = t[k_on], t[k_take]

    # ---- giver hand (= object until the take): extend toward the meeting point, within reach
    smooth_xy = _moving_average(xy, int(0.5 * rate_hz) | 1)
    meet_xy = smooth_xy + meet_fwd * forward + meet_right * right
    rel = meet_xy - giver
    dist = np.linalg.norm(rel, axis=1, keepdims=True)
    meet_xy = giver + rel * np.minimum(1.0, giver_reach / np.maximum(dist, 1e-9))
    z_track = meet_z + (peak_z - meet_z) * _smoothstep((t_take - t) / descend_time)
    w = _smoothstep((t - t_on) / extend_time)[:, None]
    giver_hand = np.concatenate(
        [home[:2] + w * (meet_xy - home[:2]), home[2] + w * (z_track[:, None] - home[2])], axis=1
    )

    # ---- receiver hand: reach until the take
    shoulder = trajectory.shoulder_position(xy, heading, walker.height)
    to_obj = giver_hand - shoulder
    u = to_obj / np.maximum(np.linalg.norm(to_obj, axis=1, keepdims=True), 1e-9)
    # Ease-in: the hand closes in on the object fastest at the end, so the hand-object distance
    # has a sharp minimum at the take, as in the recordings.
    reach = np.clip((t - (t_take - reach_time)) / reach_time, 0.0, 1.0) ** 2
    hand = trajectory.hand_position(
        xy,
        heading,
        walker.height,
        target_xyz=giver_hand - contact * u,
        reach=reach,
        swing_phase=traj.gait_phase,
    )
    obj = giver_hand.copy()

    # ---- after the take: the receiver holds the object, pulls it in and carries it on
    if k_take < n - 1:
        after = slice(k_take + 1, n)
        grip0 = hand[k_take]
        u0 = u[k_take]
        off = np.array([grip0[:2] - xy[k_take]])
        body = np.stack(
            [off @ forward[k_take], off @ right[k_take]], axis=-1
        )  # grip point in the body frame at the take
        target_xy = xy[after] + body[0, 0] * forward[after] + body[0, 1] * right[after]
        target = np.concatenate([target_xy, np.full((target_xy.shape[0], 1), grip0[2])], axis=1)
        tau = (t[after] - t_take) / pull_time
        r_after = 1.0 - (1.0 - carry_reach) * _smoothstep(tau)
        grip = trajectory.hand_position(
            xy[after],
            heading[after],
            walker.height,
            target_xyz=target,
            reach=r_after,
            swing_phase=traj.gait_phase[after],
        )
        # the object sits beyond the grip point; the tracked hand joint settles a little off it
        settle = np.clip((t[after] - t_take) / 0.3, 0.0, 1.0)
        d = contact + (hold_distance - contact) * (1.0 - (1.0 - settle) ** 2)  # ease-out
        hand[after] = grip
        obj[after] = grip + d[:, None] * u0

    # ---- orientation: yaw follows the giver's arm sweep, then the receiver's heading
    bearing = np.unwrap(np.arctan2(obj[:, 1] - giver[1], obj[:, 0] - giver[0]))
    yaw = yaw_gain * (bearing - bearing[0])
    if k_take < n - 1:
        yaw[k_take + 1 :] = yaw[k_take] + (heading[k_take + 1 :] - heading[k_take])
    quat = _yaw_quaternions(yaw, tilt)

    # ---- measurement noise
    rho = noise.drift_correlation
    xy_m = (
        xy
        + rng.standard_normal((n, 2)) * noise.pelvis_white
        + _ar1(rng, n, 2, noise.pelvis_drift, rho)
    )
    hand_m = (
        hand
        + rng.standard_normal((n, 3)) * noise.hand_white
        + _ar1(rng, n, 3, noise.hand_drift, rho)
    )
    obj_m = obj + rng.standard_normal((n, 3)) * noise.object_white
    quat_m = quat + rng.standard_normal((n, 4)) * noise.quat_white
    quat_m /= np.linalg.norm(quat_m, axis=1, keepdims=True)
    return Episode(
        receiver_xy=xy_m,
        receiver_hand_xyz=hand_m,
        giver_xyz=obj_m,
        object_quat=quat_m,
        is_ood=kind == "ood",
        source_id=source_id,
    )


def generate_synthetic(
    n: int = 1000,
    ood_fraction: float = 0.1,
    seed: int = 0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    noise: NoiseModel | None = None,
    progress: bool = False,
) -> HandoverDataset:
    """``n`` synthetic handovers: ``round(n * ood_fraction)`` OOD after ``n - that`` ID ones.

    Deterministic under ``seed``. Episode ``i`` of each kind depends only on ``(seed, kind, i)``,
    so a smaller set is a prefix of a larger one with the same seed and fraction of each kind.

    Args:
        n: number of episodes (>= 1).
        ood_fraction: fraction of OOD episodes, in [0, 1].
        seed: random seed.
        rate_hz: sampling rate (30 Hz like the public data).
        noise: measurement noise model; ``NoiseModel()`` by default.
        progress: show a tqdm progress bar.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    if not 0.0 <= float(ood_fraction) <= 1.0:
        raise ValueError(f"ood_fraction must be in [0, 1], got {ood_fraction!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    n_ood = round(n * float(ood_fraction))
    plan = [("id", i) for i in range(n - n_ood)] + [("ood", i) for i in range(n_ood)]
    episodes = []
    for kind, i in tqdm(plan, desc="synthesising", unit="episode", disable=not progress):
        rng = np.random.default_rng(
            np.random.SeedSequence([int(seed), 0 if kind == "id" else 1, i])
        )
        episodes.append(synthesize_episode(rng, kind, f"synth_{kind}_{i:04d}", rate_hz, noise))
    return HandoverDataset(
        episodes,
        rate_hz=rate_hz,
        name=f"synthetic(n={n}, ood_fraction={ood_fraction}, seed={seed})",
    )


@functools.lru_cache(maxsize=1)
def _default_episodes() -> tuple[Episode, ...]:
    return tuple(generate_synthetic().episodes)


def default_dataset() -> HandoverDataset:
    """The embedded default: ``generate_synthetic()`` (900 ID + 100 OOD, seed 0), cached per
    process."""
    return HandoverDataset(
        list(_default_episodes()), rate_hz=DEFAULT_RATE_HZ, name="synthetic(default)"
    )
