"""The flat observation layout shared by both handover envs and every agent.

The env returns one float32 vector (SB3 works out of the box); :class:`ObsLayout` names its
parts. Agents read them through its views instead of hard-coding offsets: the flags
(:meth:`~ObsLayout.object_held`, :meth:`~ObsLayout.gripper_open`,
:meth:`~ObsLayout.robot_enabled`), the frame count (:meth:`~ObsLayout.frames_seen`), the valid
receiver track (:meth:`~ObsLayout.receiver_track`), any one part (:meth:`~ObsLayout.part`) or
all of them (:meth:`~ObsLayout.unflatten`).

| key | shape | unit / meaning |
|---|---|---|
| receiver_xy_history | (W, 2) | m, camera track of the receiver base xy at 30 Hz, oldest first |
| receiver_frames_seen | (1,) | number of camera frames observed so far (history is valid from |
| | | index W - min(W, n) on; earlier rows repeat the first frame) |
| ee_pos | (3,) | m, gripper TCP position |
| ee_quat | (4,) | TCP orientation (w, x, y, z) |
| ee_linvel | (3,) | m/s |
| ee_angvel | (3,) | rad/s |
| object_pos | (3,) | m |
| object_held | (1,) | 1 while the gripper holds the object, else 0 |
| wrist_force | (3,) | N, external force at the wrist F/T sensor (gravity-compensated) |
| wrist_torque | (3,) | N*m, external torque at the wrist sensor |
| gripper_open | (1,) | 1 once the gripper has released |
| time | (1,) | s since reset |
| receiver_hand_xyz | (3,) | m, camera estimate of the receiver's right hand (same latency and |
| | | noise as the base track) |
| robot_enabled | (1,) | 1 once the robot may move (static env: after the hand was |
| | | detected and the stabilisation delay passed; dynamic env: always) |
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

POS_LIMIT = 10.0  # m; the scene fits well inside a 20 m square
VEL_LIMIT = 20.0  # m/s and rad/s
FORCE_LIMIT = 1000.0  # N
TORQUE_LIMIT = 500.0  # N*m
TIME_LIMIT = 3600.0  # s


@dataclass(frozen=True)
class ObsLayout:
    """Named slices of the flat observation vector.

    Args:
        history: W, the number of 30 Hz camera frames of receiver history in each observation.
    """

    history: int = 30
    fields: tuple[tuple[str, tuple[int, ...], float], ...] = field(init=False)

    def __post_init__(self) -> None:
        if self.history < 2:
            raise ValueError(f"history must be >= 2 frames, got {self.history}")
        object.__setattr__(
            self,
            "fields",
            (
                ("receiver_xy_history", (self.history, 2), POS_LIMIT),
                ("receiver_frames_seen", (1,), 1e6),
                ("ee_pos", (3,), POS_LIMIT),
                ("ee_quat", (4,), 1.0),
                ("ee_linvel", (3,), VEL_LIMIT),
                ("ee_angvel", (3,), VEL_LIMIT),
                ("object_pos", (3,), POS_LIMIT),
                ("object_held", (1,), 1.0),
                ("wrist_force", (3,), FORCE_LIMIT),
                ("wrist_torque", (3,), TORQUE_LIMIT),
                ("gripper_open", (1,), 1.0),
                ("time", (1,), TIME_LIMIT),
                ("receiver_hand_xyz", (3,), POS_LIMIT),
                ("robot_enabled", (1,), 1.0),
            ),
        )
        out, start = {}, 0
        for name, shape, _ in self.fields:
            n = int(np.prod(shape))
            out[name] = (slice(start, start + n), shape)
            start += n
        object.__setattr__(self, "_slices", out)
        object.__setattr__(self, "_size", start)

    @property
    def size(self) -> int:
        """Length of the flat vector."""
        return self._size  # type: ignore[attr-defined]

    def slices(self) -> dict[str, tuple[slice, tuple[int, ...]]]:
        """Name -> (slice into the flat vector, shape) (a fresh dict; computed once per layout)."""
        return dict(self._slices)  # type: ignore[attr-defined]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Finite float32 (low, high) for the observation Box."""
        high = np.concatenate(
            [np.full(int(np.prod(s)), lim, dtype=np.float32) for _, s, lim in self.fields]
        )
        low = -high
        for name in (
            "receiver_frames_seen",
            "object_held",
            "gripper_open",
            "time",
            "robot_enabled",
        ):
            low[self.slices()[name][0]] = 0.0
        return low, high

    def unflatten(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Split a flat observation into named copies (they never share memory with ``obs``)."""
        obs = np.asarray(obs)
        if obs.shape != (self.size,):
            raise ValueError(f"observation must have shape ({self.size},), got {obs.shape}")
        return {name: obs[sl].reshape(shape).copy() for name, (sl, shape) in self.slices().items()}

    def flatten(self, parts: dict[str, np.ndarray]) -> np.ndarray:
        """Pack named parts into a float32 vector clipped to :meth:`bounds`."""
        missing = [name for name, _, _ in self.fields if name not in parts]
        if missing:
            raise KeyError(f"missing observation parts: {missing}")
        out = np.concatenate(
            [np.asarray(parts[name], dtype=np.float64).reshape(-1) for name, _, _ in self.fields]
        ).astype(np.float32)
        if out.shape != (self.size,):
            raise ValueError(f"parts give {out.shape[0]} values, layout needs {self.size}")
        low, high = self.bounds()
        return np.clip(out, low, high)

    # ------------------------------------------------------------------ named views
    def _checked(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs)
        if obs.shape != (self.size,):
            raise ValueError(f"observation must have shape ({self.size},), got {obs.shape}")
        return obs

    def _flag(self, obs: np.ndarray, name: str) -> bool:
        return bool(self._checked(obs)[self._slices[name][0].start] > 0.5)  # type: ignore[attr-defined]

    def part(self, obs: np.ndarray, name: str) -> np.ndarray:
        """One named part of ``obs``, in its shape and ``obs``'s dtype (a copy)."""
        if name not in self._slices:  # type: ignore[attr-defined]
            raise KeyError(f"no observation part {name!r}; parts: {[f[0] for f in self.fields]}")
        sl, shape = self._slices[name]  # type: ignore[attr-defined]
        return self._checked(obs)[sl].reshape(shape).copy()

    def object_held(self, obs: np.ndarray) -> bool:
        """The gripper holds the object (``object_held`` > 0.5)."""
        return self._flag(obs, "object_held")

    def gripper_open(self, obs: np.ndarray) -> bool:
        """The gripper has released (``gripper_open`` > 0.5)."""
        return self._flag(obs, "gripper_open")

    def robot_enabled(self, obs: np.ndarray) -> bool:
        """The robot may move (``robot_enabled`` > 0.5)."""
        return self._flag(obs, "robot_enabled")

    def frames_seen(self, obs: np.ndarray) -> int:
        """Camera frames of the receiver delivered so far (``receiver_frames_seen``, rounded)."""
        sl = self._slices["receiver_frames_seen"][0]  # type: ignore[attr-defined]
        return int(round(float(self._checked(obs)[sl.start])))

    def receiver_track(self, obs: np.ndarray) -> np.ndarray:
        """The valid part of the receiver history in ``obs``: (n, 2) with n = min(W, frames
        seen), at least 1 (before the first frame: the placeholder row); ``obs``'s dtype, a
        copy."""
        obs = self._checked(obs)
        n = min(self.history, max(1, self.frames_seen(obs)))
        sl = self._slices["receiver_xy_history"][0]  # type: ignore[attr-defined]
        return obs[sl].reshape(self.history, 2)[-n:].copy()
