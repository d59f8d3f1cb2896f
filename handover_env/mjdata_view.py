"""MjData's numeric fields as one float64 array, for compiled kernels.

MuJoCo allocates the fixed-size arrays of an ``MjData`` (``qpos``, ``qvel``, ``ctrl``,
``qfrc_applied``, ``sensordata``, ``xpos``, ``xmat``, ``site_xpos``, ``cdof``, ``cvel``, ``cacc``,
``qfrc_bias``, ...) in one buffer that never moves while the ``MjData`` lives. A compiled kernel
reads and writes them through :attr:`MjDataView.mem`, one float64 array over that buffer, at the
offsets :meth:`MjDataView.offset` gives (in float64 elements). One array argument instead of one
per field keeps a kernel's call cost at its minimum (numba checks the type of every argument at
every call).

The offsets are taken from the binding's own arrays, so a kernel touches exactly the memory the
binding exposes; nothing outside those fields is read or written. :class:`MjDataView` keeps a
reference to the ``MjData``, so the memory stays valid as long as the view does.
"""

from __future__ import annotations

import ctypes

import mujoco
import numpy as np

#: The fields a kernel may use (float64 arrays of MuJoCo's fixed-size buffer).
FIELDS = (
    "qpos", "qvel", "ctrl", "qfrc_applied", "sensordata", "xpos", "xmat", "xipos",
    "site_xpos", "site_xmat", "subtree_com", "cdof", "cvel", "cacc", "qfrc_bias",
)
#: The largest span the fields may cover (they are in one allocation; a far larger span would
#: mean a MuJoCo whose layout this module does not know).
MAX_SPAN_BYTES = 1 << 30


class MjDataView:
    """One float64 array (:attr:`mem`) over the fields of ``data`` in :data:`FIELDS`.

    Raises:
        ValueError: a field is not a float64 array aligned to 8 bytes, or the fields span more
            than :data:`MAX_SPAN_BYTES` (not one allocation).
    """

    def __init__(self, data: mujoco.MjData) -> None:
        self.data = data  # keeps the memory alive
        arrays = {name: np.asarray(getattr(data, name)) for name in FIELDS}
        starts = [a.ctypes.data for a in arrays.values() if a.size]
        ends = [a.ctypes.data + a.nbytes for a in arrays.values() if a.size]
        base, end = min(starts), max(ends)
        if end - base > MAX_SPAN_BYTES:
            raise ValueError(f"MjData fields span {end - base} bytes: not one buffer")
        self._offsets: dict[str, int] = {}
        for name, a in arrays.items():
            if a.dtype != np.float64 or (a.ctypes.data - base) % 8:
                raise ValueError(f"MjData.{name} is not an aligned float64 array")
            if not a.flags.c_contiguous:
                raise ValueError(f"MjData.{name} is not contiguous")
            self._offsets[name] = (a.ctypes.data - base) // 8
        n = (end - base) // 8
        self.mem: np.ndarray = np.frombuffer((ctypes.c_double * n).from_address(base),
                                             dtype=np.float64)

    def offset(self, name: str, row: int = 0, width: int | None = None) -> int:
        """Offset (float64 elements) in :attr:`mem` of row ``row`` of field ``name`` (a row of
        ``width`` numbers: the field's second dimension unless given)."""
        a = np.asarray(getattr(self.data, name))
        if width is None:
            width = a.shape[1] if a.ndim == 2 else 1
        return self._offsets[name] + row * width
