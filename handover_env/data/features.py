"""The exact inputs and outputs shared by the learned baselines (BC-MLP and ACT).

"The same information the planner sees" (issue 5): the planner observes the receiver's base xy at
30 Hz up to the current frame, and the robot knows where its own gripper is. Both baselines get
exactly that, packed the same way, at every frame ``t`` of an episode:

| name | LeRobot key | shape | content |
|---|---|---|---|
| environment state | ``observation.environment_state`` | (2 W,) | receiver base xy, last W frames |
| giver state | ``observation.state`` | (3,) | giver wrist xyz at frame t (m) |
| action chunk | ``action`` (+ ``delta_timestamps``)| (H, 3) | giver wrist xyz, frames t..t+H-1 |

**Receiver history encoding** (``encode_receiver``), W frames ``p_{t-W+1} .. p_t`` of base xy (m):

* entries 0-1: the absolute current position ``p_t`` (x, y), in the dataset frame (giver/robot
  near the origin). The absolute position matters: where the receiver is relative to the giver
  decides where the handover happens.
* entries 2..2W-1: the W-1 earlier positions relative to the current one, ``p_{t-k} - p_t`` for
  k = W-1, ..., 1 (oldest first), flattened (x, y, x, y, ...). These carry velocity, heading and
  gait without depending on where the walk happens.
* Before W frames exist (start of an episode or of an env run) the missing frames repeat the first
  observed frame, exactly like the env's observation buffer (``ObsLayout``), so their offsets are
  ``p_0 - p_t``.

**Giver state** is the giver wrist (the object) at the current frame in the data, and the robot's
TCP position (``ee_pos``) in the env. Giving it to the learned baselines is fair: ACT's design
conditions on proprioception, the robot always knows it, and in the open-loop protocol the giver
position at the current frame is part of the recorded past. (Row 0 of the target is this same
frame, so a baseline can copy it; rows 1..H-1 are the prediction.)

**Target** (``action``) is the absolute giver xyz (m) for frames t .. t+H-1 (row 0 = the current
frame, as in the open-loop protocol). Past the episode end the chunk repeats the last frame and is
masked out of the loss by ``action_is_pad``, LeRobot's convention for ``delta_timestamps``.

All features are float32 at the dataset rate (30 Hz). W (``history``) defaults to 10 frames (1/3 s);
H (``horizon``) to 30 frames (1 s, the paper's chunk size).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handover_env.data.dataset import Episode, HandoverDataset

OBS_ENV_STATE = "observation.environment_state"
OBS_STATE = "observation.state"
ACTION = "action"
STATE_DIM = 3
ACTION_DIM = 3


@dataclass(frozen=True)
class FeatureSpec:
    """Window sizes of the shared baseline features.

    Args:
        history: W, frames of receiver base xy history in the environment state (>= 2).
        horizon: H, frames of future giver xyz in the predicted chunk (>= 1).
        rate_hz: the dataset rate the features are built at.
    """

    history: int = 10
    horizon: int = 30
    rate_hz: float = 30.0

    def __post_init__(self) -> None:
        if not isinstance(self.history, (int, np.integer)) or self.history < 2:
            raise ValueError(f"history must be an integer >= 2 frames, got {self.history!r}")
        if not isinstance(self.horizon, (int, np.integer)) or self.horizon < 1:
            raise ValueError(f"horizon must be an integer >= 1 frame, got {self.horizon!r}")
        if not np.isfinite(self.rate_hz) or self.rate_hz <= 0:
            raise ValueError(f"rate_hz must be positive, got {self.rate_hz!r}")

    @property
    def env_dim(self) -> int:
        """Length of the environment-state vector, 2 W."""
        return 2 * self.history

    def to_dict(self) -> dict:
        return {
            "history": int(self.history),
            "horizon": int(self.horizon),
            "rate_hz": float(self.rate_hz),
        }


def receiver_windows(receiver_xy: np.ndarray, times: np.ndarray, history: int) -> np.ndarray:
    """The W-frame windows ending at each of ``times``: (Q, W, 2), front-padded with frame 0."""
    receiver_xy = np.asarray(receiver_xy, dtype=np.float64)
    times = np.asarray(times, dtype=np.int64).reshape(-1)
    idx = times[:, None] + np.arange(-history + 1, 1)[None, :]
    return receiver_xy[np.clip(idx, 0, None)]


def encode_receiver(window: np.ndarray) -> np.ndarray:
    """Encode (..., W, 2) windows (oldest first) as (..., 2 W) environment-state vectors."""
    window = np.asarray(window, dtype=np.float64)
    if window.ndim < 2 or window.shape[-1] != 2 or window.shape[-2] < 2:
        raise ValueError(f"receiver window must have shape (..., W>=2, 2), got {window.shape}")
    current = window[..., -1, :]
    rel = window[..., :-1, :] - current[..., None, :]
    return np.concatenate([current, rel.reshape(*rel.shape[:-2], -1)], axis=-1)


def encode_history(receiver_history: np.ndarray, history: int) -> np.ndarray:
    """Environment state (2 W,) from an observed (T, 2) history (the last W frames are used)."""
    receiver_history = np.asarray(receiver_history, dtype=np.float64)
    window = receiver_windows(receiver_history, np.array([receiver_history.shape[0] - 1]), history)[
        0
    ]
    return encode_receiver(window)


def check_dataset(dataset: HandoverDataset, spec: FeatureSpec) -> None:
    """Raise a clear ``ValueError`` when ``dataset`` cannot feed baselines built with ``spec``."""
    if len(dataset) == 0:
        raise ValueError("the dataset has no episodes")
    if abs(dataset.rate_hz - spec.rate_hz) > 1e-6:
        raise ValueError(
            f"dataset rate is {dataset.rate_hz} Hz, the baseline features need {spec.rate_hz} Hz"
        )
    short = [(ep.source_id, ep.length) for ep in dataset if ep.length < spec.horizon]
    if short:
        sid, n = short[0]
        raise ValueError(
            f"horizon H={spec.horizon} frames is longer than {len(short)} episode(s), e.g. {sid!r} "
            f"with {n} frames; use a shorter --horizon or drop the short episodes"
        )


@dataclass(frozen=True)
class FrameArrays:
    """Per-frame training samples of one or more episodes (all float32 except the mask and ids).

    Attributes:
        env_state: (N, 2W) receiver history features.
        state: (N, 3) giver xyz at the frame.
        action: (N, H, 3) giver xyz chunk from the frame on.
        action_is_pad: (N, H) True where the chunk runs past the episode end.
        episode: (N,) index of the episode each sample comes from.
        frame: (N,) frame index within its episode.
    """

    env_state: np.ndarray
    state: np.ndarray
    action: np.ndarray
    action_is_pad: np.ndarray
    episode: np.ndarray
    frame: np.ndarray

    def __len__(self) -> int:
        return int(self.env_state.shape[0])


def episode_frames(ep: Episode, spec: FeatureSpec, times: np.ndarray | None = None) -> FrameArrays:
    """Features of ``ep`` at ``times`` (default: every frame)."""
    T = ep.length
    t = np.arange(T) if times is None else np.asarray(times, dtype=np.int64).reshape(-1)
    if t.size and (t.min() < 0 or t.max() >= T):
        raise ValueError(f"frame indices must lie in [0, {T - 1}] for episode {ep.source_id!r}")
    env = encode_receiver(receiver_windows(ep.receiver_xy, t, spec.history))
    fut = t[:, None] + np.arange(spec.horizon)[None, :]
    return FrameArrays(
        env_state=env.astype(np.float32),
        state=ep.giver_xyz[t].astype(np.float32),
        action=ep.giver_xyz[np.minimum(fut, T - 1)].astype(np.float32),
        action_is_pad=fut >= T,
        episode=np.zeros(t.size, dtype=np.int64),
        frame=t,
    )


def dataset_frames(dataset: HandoverDataset, spec: FeatureSpec) -> FrameArrays:
    """Features of every frame of every episode, concatenated in episode order."""
    check_dataset(dataset, spec)
    parts = [episode_frames(ep, spec) for ep in dataset]
    return FrameArrays(
        env_state=np.concatenate([p.env_state for p in parts]),
        state=np.concatenate([p.state for p in parts]),
        action=np.concatenate([p.action for p in parts]),
        action_is_pad=np.concatenate([p.action_is_pad for p in parts]),
        episode=np.concatenate([np.full(len(p), i, dtype=np.int64) for i, p in enumerate(parts)]),
        frame=np.concatenate([p.frame for p in parts]),
    )


def validate_giver(giver_xyz: np.ndarray | None) -> np.ndarray:
    """Return the current giver xyz as float64 (3,) or raise a clear ``ValueError``."""
    if giver_xyz is None:
        raise ValueError(
            "the learned baselines condition on the current giver/robot xyz: pass giver_xyz "
            "(open loop: the episode's giver at the current frame; env: obs ee_pos)"
        )
    arr = np.asarray(giver_xyz, dtype=np.float64).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"giver_xyz must be 3 finite numbers, got {np.asarray(giver_xyz).shape}")
    return arr


def split_train_val(
    dataset: HandoverDataset, val_fraction: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Episode indices (train, val), stratified by ID/OOD; val is one of round(1/val_fraction)
    folds.

    With too few episodes for a stratified split (tests, tiny sets) it falls back to a seeded
    random split that still keeps at least one episode on each side.
    """
    if not 0.0 < val_fraction < 1.0:
        raise ValueError(f"val_fraction must be in (0, 1), got {val_fraction!r}")
    n = len(dataset)
    if n < 2:
        raise ValueError(f"need at least 2 episodes for a train/validation split, got {n}")
    k = max(2, int(round(1.0 / val_fraction)))
    try:
        train, val = dataset.stratified_kfold(k, seed=seed)[0]
    except ValueError:
        perm = np.random.default_rng(seed).permutation(n)
        n_val = min(n - 1, max(1, int(round(val_fraction * n))))
        val, train = np.sort(perm[:n_val]), np.sort(perm[n_val:])
    return np.asarray(train), np.asarray(val)


def facing_yaw(target_xyz: np.ndarray, receiver_xy: np.ndarray) -> float:
    """Gripper yaw (rad) that points from the target position toward the receiver's base."""
    d = np.asarray(receiver_xy, dtype=np.float64)[:2] - np.asarray(target_xyz, dtype=np.float64)[:2]
    return float(np.arctan2(d[1], d[0])) if np.hypot(*d) > 1e-9 else 0.0

