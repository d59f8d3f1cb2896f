"""The benchmark's outcome taxonomy (protocols v1, v2): one cause per failed episode, every flag.

The env ends an episode at its first terminal condition (``info["outcome"]``), but a failed
handover often fails more than one check on the way (a release before the grasp *and* a miss; a
MuJoCo instability mid-episode *and* a success afterwards). As R2HandoverSim charges each failed
trial to its first failed check, a failed episode is charged to the first check of
:data:`CHECKS` it fails, in this stated order (the handover's own order: the simulation must be
valid, the person safe, the object released only into a hand, the person must reach, grasp,
and get the object released and cleared):

1. ``unstable``: MuJoCo found the simulation unstable (any bad qpos/qvel/qacc, or the
   ``unstable`` outcome); the episode is void, and never a success even if it ended as one.
2. ``unsafe_force``: a pull or a body contact above its limit.
3. ``premature_release``: the gripper opened before the person's hand held the object.
4. ``no_reach``: the person never began to reach (the object never came within their reach).
5. ``no_grasp``: they reached but never closed their hand on the object.
6. ``no_release``: they grasped but the robot never released.
7. ``dropped``: released and then fell.
8. ``not_cleared``: any other failure (e.g. the time ran out with the object still between them).

A success (``outcome == "success"`` and no instability) has no first failure. Besides, each
episode carries every event flag of :data:`EVENTS` (HandoverSim reports an outcome bitmask for
the same reason): which checks failed, and what else happened (body contact, penetration > 1 cm,
time-out).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from handover_eval.closedloop.stats import cell_float

CHECKS: tuple[str, ...] = (
    "unstable",
    "unsafe_force",
    "premature_release",
    "no_reach",
    "no_grasp",
    "no_release",
    "dropped",
    "not_cleared",
)
#: Event flag columns (``ev_<name>``), each a bool per episode.
EVENTS: tuple[str, ...] = (
    "unstable",
    "unsafe_force",
    "premature_release",
    "reached",
    "grasped",
    "released",
    "dropped",
    "missed",
    "timeout",
    "body_contact",
    "penetration_over_1cm",
)
PENETRATION_FLAG_M = 0.01


def _flag(row: Mapping[str, Any], key: str) -> bool:
    v = row.get(key)
    return v is True or v == "True" or (isinstance(v, (int, float)) and not isinstance(v, bool)
                                        and v == 1)


def events(row: Mapping[str, Any]) -> dict[str, bool]:
    """Every event flag of one closed-loop episode row (:func:`handover_eval.episodes.
    episode_row`'s columns)."""
    outcome = row.get("outcome")
    return {
        "unstable": outcome == "unstable" or cell_float(row.get("sim_unstable")) > 0,
        "unsafe_force": outcome == "unsafe_force",
        "premature_release": outcome == "premature_release" or _flag(row, "release_before_grasp"),
        "reached": math.isfinite(cell_float(row.get("reach_onset_time"))),
        "grasped": math.isfinite(cell_float(row.get("transfer_time"))),
        "released": _flag(row, "released"),
        "dropped": outcome == "dropped",
        "missed": outcome == "missed",
        "timeout": outcome == "timeout",
        "body_contact": cell_float(row.get("body_contact_force")) > 0,
        "penetration_over_1cm": cell_float(row.get("penetration")) > PENETRATION_FLAG_M,
    }


def first_failure(outcome: str, ev: Mapping[str, bool]) -> str:
    """The first check of :data:`CHECKS` the episode fails; "" for a success."""
    if ev["unstable"]:
        return "unstable"
    if outcome == "success":
        return ""
    for check, failed in (
        ("unsafe_force", ev["unsafe_force"]),
        ("premature_release", ev["premature_release"]),
        ("no_reach", not ev["reached"]),
        ("no_grasp", not ev["grasped"]),
        ("no_release", not ev["released"]),
        ("dropped", ev["dropped"]),
    ):
        if failed:
            return check
    return "not_cleared"
