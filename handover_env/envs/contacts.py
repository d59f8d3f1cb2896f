"""Contacts between the robot, the object and the person: force per body part, penetration.

At every controller tick with contacts, :meth:`ContactMonitor.scan` sums the normal forces
(``mj_contactForce``) of the robot-person and object-person contacts (the only pairs that can
touch the person) per segment of the body, and keeps the deepest penetration. Object-person
contacts count while the robot holds the object, or while nobody does (a dropped object falling
on the person); once the person holds it alone (:attr:`ContactMonitor.count_object` False) the
object is the person's, and its contact with their own body (carrying it against the torso) is
no robot contact.

Measured force. The solver's force at the first tick of a contact includes the impulse that
removes that tick's penetration in one 5 ms step (up to several hundred newtons for a few
milliseconds, a property of the stiff contact model, not of tissue). Like the wrist F/T estimate
(15 ms) and like the force gauges used to measure collaborative-robot contacts, the force per
segment is low-pass filtered (first order, ``FORCE_FILTER_TAU`` = 10 ms); the filtered force is
what is reported (``contact_force_<segment>``) and held to the limits, and the unfiltered peak is
reported beside it (``body_contact_force_raw``).

Safety follows ISO/TS 15066:2016 (Annex A), which limits a contact force by body region and
distinguishes a *transient* contact (the person can move away; shorter than 0.5 s), allowed up to
twice the quasi-static limit, from a *quasi-static* one (clamping, or lasting longer), held to
the quasi-static limit (:data:`handover_env.person.body_model.ISO_REGIONS`). A segment is unsafe
when its force exceeds twice its region's limit at any tick, or exceeds the limit for longer than
0.5 s.
"""

from __future__ import annotations

import mujoco
import numpy as np

from handover_env.person.body_model import ISO_REGIONS
from handover_env.person.skeleton import SEGMENTS
from handover_env.robot.scene import SceneIds

ROBOT, OBJECT, PERSON = 1, 2, 4
TRANSIENT_FACTOR = 2.0  # ISO/TS 15066 Annex A: transient limits are twice the quasi-static ones
TRANSIENT_TIME = 0.5  # s: a contact over the quasi-static limit for longer is quasi-static
FORCE_FILTER_TAU = 0.010  # s, first-order low-pass of the force per segment
_FORCE_KEYS = tuple(f"contact_force_{s.name}" for s in SEGMENTS)  # info keys, segment order


class ContactMonitor:
    """Per-episode contact bookkeeping for one model.

    Attributes:
        peak: (S,) peak contact force on each body segment so far, N.
        peak_max: the largest of :attr:`peak`, N (a float).
        entries: the info entries as of the last scan (``contact_force_<segment>`` for every
            segment, the body's peak, its raw peak, penetration and the touched flags); the
            monitor's own dict: read, do not change.
        penetration: deepest robot/object-person penetration so far, m (0 if none).
        touched_robot, touched_object: whether the robot / the object touched the person.
        unsafe_segment: index of the first segment whose force exceeded its ISO limit, or -1.
        force: (S,) the filtered force per segment now, N (read only).
        count_object: whether object-person contacts count (set by the env at every tick:
            False once the person holds the object and the robot no longer does).
    """

    def __init__(self, model: mujoco.MjModel, ids: SceneIds, tick: float = 0.005) -> None:
        self.model = model
        self._alpha = tick / (FORCE_FILTER_TAU + tick)
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
        self.raw_peak = 0.0
        self._force = np.zeros(len(SEGMENTS))  # filtered force per segment
        self._now = np.zeros(len(SEGMENTS))
        #: (S,) the robot's normal force on each segment at the last scanned tick, N (unfiltered:
        #: what the person feels, :meth:`handover_env.person.receiver.Receiver.feel`).
        self.robot_now = np.zeros(len(SEGMENTS))
        self._over_since = np.full(len(SEGMENTS), np.nan)  # when the force went over the limit
        #: True while some segment's filtered force has not decayed (keep scanning every tick).
        self.active = False
        self.penetration = 0.0
        self.count_object = True
        self.touched_robot = False
        self.touched_object = False
        self.unsafe_segment = -1
        self._summarise()

    def scan(self, data: mujoco.MjData) -> None:
        """Look at this tick's contacts (call at every tick with contacts, and while
        :attr:`active`, so that the filtered forces decay and quasi-static timing restarts)."""
        cls, seg = self._cls, self._segment
        now, robot_now = self._now, self.robot_now
        now[:] = 0.0
        robot_now[:] = 0.0
        for i in range(data.ncon):
            c = data.contact[i]
            g1, g2 = c.geom1, c.geom2
            pair = cls[g1] | cls[g2]
            if pair != ROBOT | PERSON and (pair != OBJECT | PERSON or not self.count_object):
                continue
            mujoco.mj_contactForce(self.model, data, i, self._force6)
            s = int(seg[g1] if seg[g1] >= 0 else seg[g2])
            f = abs(float(self._force6[0]))
            now[s] += f
            if -c.dist > self.penetration:
                self.penetration = -float(c.dist)
            if pair == ROBOT | PERSON:
                self.touched_robot = True
                robot_now[s] += f
            else:
                self.touched_object = True
        self.raw_peak = max(self.raw_peak, float(now.max()))
        force = self._force
        force += self._alpha * (now - force)
        np.maximum(self.peak, force, out=self.peak)
        over = force > self.limits
        if self.unsafe_segment < 0:
            hit = np.nonzero(force > TRANSIENT_FACTOR * self.limits)[0]
            if hit.size:
                self.unsafe_segment = int(hit[0])
        t = float(data.time)
        started = over & np.isnan(self._over_since)
        self._over_since[started] = t
        self._over_since[~over] = np.nan
        long = np.nonzero(t - self._over_since > TRANSIENT_TIME)[0]
        if long.size and self.unsafe_segment < 0:
            self.unsafe_segment = int(long[0])
        self.active = bool(force.max() > 1e-3)
        self._summarise()

    @property
    def force(self) -> np.ndarray:
        """(S,) N: each segment's filtered contact force as of the last scan (read only: a view
        of the monitor's own array)."""
        view = self._force.view()
        view.flags.writeable = False
        return view

    def geom_class(self, geom: int) -> int:
        """What geom ``geom`` is to the monitor: :data:`ROBOT`, :data:`OBJECT`, :data:`PERSON`,
        or 0 (the floor, anything else)."""
        return int(self._cls[geom])

    def _summarise(self) -> None:
        """The body's peak (:attr:`peak_max`) and the info entries, as of the last scan (they
        change only in :meth:`scan` and :meth:`reset`, so a step without contacts reads them)."""
        self.peak_max = float(self.peak.max())
        entries: dict[str, float | bool] = dict(zip(_FORCE_KEYS, self.peak.tolist()))
        entries["body_contact_force"] = self.peak_max
        entries["body_contact_force_raw"] = self.raw_peak
        entries["penetration"] = self.penetration
        entries["body_contact_robot"] = self.touched_robot
        entries["body_contact_object"] = self.touched_object
        self.entries = entries
