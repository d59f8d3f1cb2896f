"""Contacts between the robot, the object and the person: peak force per body part, penetration.

Every controller tick with contacts, :meth:`ContactMonitor.scan` looks at the robot-person and
object-person contacts (the only pairs that can touch the person), and keeps per segment of the
body the peak normal force (``mj_contactForce``), and over all of them the deepest penetration.

Safety follows ISO/TS 15066:2016 (Annex A), which limits a contact force by body region and
distinguishes a *transient* contact (the person can move away; shorter than 0.5 s), allowed up to
twice the quasi-static limit, from a *quasi-static* one (clamping, or lasting longer), held to
the quasi-static limit (:data:`handover_env.body_model.ISO_REGIONS`). A segment is unsafe when its
force exceeds twice its region's limit at any tick, or exceeds the limit for longer than 0.5 s.
"""

from __future__ import annotations

import mujoco
import numpy as np

from handover_env.body_model import ISO_REGIONS
from handover_env.scene import SceneIds
from handover_env.skeleton import SEGMENTS

ROBOT, OBJECT, PERSON = 1, 2, 4
TRANSIENT_FACTOR = 2.0  # ISO/TS 15066 Annex A: transient limits are twice the quasi-static ones
TRANSIENT_TIME = 0.5  # s: a contact over the quasi-static limit for longer is quasi-static


class ContactMonitor:
    """Per-episode contact bookkeeping for one model.

    Attributes:
        peak: (S,) peak contact force on each body segment so far, N.
        penetration: deepest robot/object-person penetration so far, m (0 if none).
        touched_robot, touched_object: whether the robot / the object touched the person.
        unsafe_segment: index of the first segment whose force exceeded its ISO limit, or -1.
    """

    def __init__(self, model: mujoco.MjModel, ids: SceneIds) -> None:
        self.model = model
        self._cls = np.zeros(model.ngeom, dtype=np.int8)
        self._cls[ids.robot_geoms] = ROBOT
        self._cls[ids.object_geom] = OBJECT
        self._cls[ids.receiver_geoms] = PERSON
        self._segment = np.full(model.ngeom, -1, dtype=np.int64)
        self._segment[ids.receiver_geoms] = ids.body.geom_segment
        self.limits = np.array([ISO_REGIONS[s.region][1] for s in SEGMENTS])
        self._force6 = np.zeros(6)
        self.reset()

    def reset(self) -> None:
        self.peak = np.zeros(len(SEGMENTS))
        self._over_since = np.full(len(SEGMENTS), np.nan)  # when the force went over the limit
        self._over_now = np.zeros(len(SEGMENTS), dtype=bool)
        #: True while some segment is over its quasi-static limit (keep scanning at every tick).
        self.active = False
        self.penetration = 0.0
        self.touched_robot = False
        self.touched_object = False
        self.unsafe_segment = -1

    def scan(self, data: mujoco.MjData) -> None:
        """Look at this tick's contacts (call at every tick with contacts, and once at the first
        tick without after one with, so that quasi-static timing restarts)."""
        cls, seg = self._cls, self._segment
        over = self._over_now
        over[:] = False
        for i in range(data.ncon):
            c = data.contact[i]
            g1, g2 = c.geom1, c.geom2
            pair = cls[g1] | cls[g2]
            if pair != ROBOT | PERSON and pair != OBJECT | PERSON:
                continue
            mujoco.mj_contactForce(self.model, data, i, self._force6)
            force = abs(float(self._force6[0]))
            s = int(seg[g1] if seg[g1] >= 0 else seg[g2])
            self.peak[s] = max(self.peak[s], force)
            if force > self.limits[s]:
                over[s] = True
                if force > TRANSIENT_FACTOR * self.limits[s] and self.unsafe_segment < 0:
                    self.unsafe_segment = s
            if -c.dist > self.penetration:
                self.penetration = -float(c.dist)
            if pair == ROBOT | PERSON:
                self.touched_robot = True
            else:
                self.touched_object = True
        t = float(data.time)
        started = over & np.isnan(self._over_since)
        self._over_since[started] = t
        self._over_since[~over] = np.nan
        long = np.nonzero(t - self._over_since > TRANSIENT_TIME)[0]
        if long.size and self.unsafe_segment < 0:
            self.unsafe_segment = int(long[0])
        self.active = bool(over.any())

    def info(self) -> dict[str, float | bool]:
        """Flat info entries: ``contact_force_<segment>`` for every segment, the body's peak,
        penetration and the touched flags."""
        out: dict[str, float | bool] = {f"contact_force_{s.name}": float(self.peak[i]) for i, s in enumerate(SEGMENTS)}
        out["body_contact_force"] = float(self.peak.max())
        out["penetration"] = self.penetration
        out["body_contact_robot"] = self.touched_robot
        out["body_contact_object"] = self.touched_object
        return out
