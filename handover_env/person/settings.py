"""How the simulated person reaches, grasps, holds, slows down and pulls: :class:`ReceiverConfig`.

The settings of :class:`handover_env.person.receiver.Receiver` (the envs' ``person=`` overrides),
each a real number within a stated range (:data:`SETTING_RANGES`) or an opt-in switch
(:data:`SWITCHES`, True or False), and the checks of the numeric reset options (``height``,
``speed``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from handover_env.numbers import checked_number
from handover_env.person.person import RATE

#: Speed up to which a segment's target is led by the feed-forward, m/s (peak hand speeds of
#: fast human reaches are about 2-3 m/s).
MAX_SEGMENT_SPEED = 3.0
#: An object behind the person counts as walked past only if it is within this distance, m.
PASS_DISTANCE = 1.2

# Ranges of the person settings (ReceiverConfig; the envs' ``person=`` overrides). A value
# outside its range is refused with the setting and the range named.
#: The env's longest episode, s (StaticHandover-v0: 600 steps at 30 Hz): a slower movement never
#: ends within an episode.
LONGEST_EPISODE = 20.0
#: The shortest movement, s: one env step (the hand's path is re-planned once per step).
SHORTEST_MOVE = 1.0 / RATE
#: The longest arm's reach, m: shoulder to grip centre of a 2.3 m body (ARM_REACH_RATIO 0.386).
LONGEST_REACH = 0.9
#: The ``height`` reset option's range, m (adults; the walker model itself takes 1.0 .. 2.3).
HEIGHT_OPTION_RANGE = (1.2, 2.2)
#: Half the height of the bottle handed over, m (handover_env/assets/scene.xml: size 0.033 0.1).
OBJECT_HALF_HEIGHT = 0.1
#: (low, high, unit, where the range comes from) of every ReceiverConfig field.
SETTING_RANGES: dict[str, tuple[float, float, str, str]] = {
    "reach_duration": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "reach_lead_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "comfort_fraction": (0.1, 2.0, "", "of the arm's length"),
    "min_speed_factor": (0.05, 1.0, "", "a waiting person walks at least 1/20 of their speed"),
    "slow_rate": (1.0 / LONGEST_EPISODE, RATE, "1/s",
                  "changes the speed factor by 1 over the longest episode .. in one env step"),
    "give_up_behind": (0.0, 1.0, "m", f"an object is walked past only within {PASS_DISTANCE} m"),
    "hold_time": (0.0, LONGEST_EPISODE, "s", "up to the longest episode"),
    "pull_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "pull_distance": (0.0, LONGEST_REACH, "m", "within the longest reach"),
    "grasp_radius": (0.005, 2 * OBJECT_HALF_HEIGHT, "m", "5 mm .. the bottle's height"),
    "grasp_speed": (0.01, MAX_SEGMENT_SPEED, "m/s", "up to a fast human hand"),
    "grasp_offset": (-OBJECT_HALF_HEIGHT, OBJECT_HALF_HEIGHT, "m",
                     "on the bottle's axis, within its half-height"),
    "approach_distance": (0.0, 0.5 * LONGEST_REACH, "m", "within half the longest reach"),
    "approach_height": (0.0, 0.5 * LONGEST_REACH, "m", "within half the longest reach"),
    "close_radius": (0.005, LONGEST_REACH, "m", "5 mm .. the longest reach"),
    "close_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "carry_forward": (0.0, 0.5 * LONGEST_REACH, "m", "within half the longest reach"),
    "present_time": (SHORTEST_MOVE, LONGEST_EPISODE, "s", "one env step .. the longest episode"),
    "present_reach": (0.005, LONGEST_REACH, "m", "5 mm .. the longest reach"),
}
#: The person's behaviours that can be switched (True or False; docs/simulator.md "Person
#: switches"): ``reach_offset`` (a person's own reach, :mod:`handover_env.person.take`; on),
#: ``arm_yield`` (the reaching arm yields to the robot, :mod:`handover_env.person.arm_yield`;
#: on), ``avoid_gripper`` (the held object leaves the gripper by its open side,
#: :func:`handover_env.person.hand_path.hand_kernel`; on), ``grasp_below`` (the modelled hand
#: takes the object's lower part; on), ``recorded_elbow`` (the elbow held down and back as the
#: recorded receivers held it; on) and ``joint_damping`` (a passive damping in every joint of
#: the body, :data:`handover_env.person.body_model.PASSIVE_JOINT_DAMPING`; off).
SWITCHES = ("reach_offset", "arm_yield", "avoid_gripper", "grasp_below", "recorded_elbow",
            "joint_damping")


@dataclass(frozen=True)
class ReceiverConfig:
    """How the person reaches, grasps, holds, slows down and pulls (see the module docstring).

    The defaults are calibrated on the calibration half (Table I folds 0-4) of the development
    copy's ID recordings by ``handover-data transfer-stats``
    (``docs/calibration/receiver_calibration.md``; medians unless said otherwise):

    Args:
        reach_duration: the longest the hand's first plan takes from the reach onset to the
            grasp, s (onset to transfer, 0.63; re-planned while the person pauses or turns).
        reach_lead_time: the reach starts when the person will meet the object (within their take
            distance, :mod:`handover_env.person.receiver_rules`) within this time, s (the onset
            leads the transfer by the reach duration, 0.63); the object's motion is extrapolated
            over it.
        comfort_fraction: the farthest people take the object from, as a fraction of their arm
            length (shoulder-elbow-wrist-hand joints): p95 of the object-shoulder distance over
            the arm length at transfer, 1.10 (median 0.86; the grip centre lies beyond the hand
            joint, and the trunk turns toward the object). People start to reach for an object
            that they can reach when they meet it (straight arm and turned trunk); if it will be
            farther than this fraction, they also slow down (down to ``min_speed_factor``).
        min_speed_factor: the slowest people walk while waiting for the object, as a fraction of
            their own speed (p25 of the minimum walking speed in the handover window relative to
            the speed before the reach, 0.82; the median, 0.91, is above the same measure in a
            window without a handover, 0.75: people do not slow down for a handover that is on
            time). ``slow_rate``: how fast the speed factor changes, 1/s.
        give_up_behind: an unheld object this far behind the shoulder (along the walk) is left
            behind, if the rest of the person's walk never brings it ahead of them again: the
            person walks past, m.
        hold_time: after the grasp the arm stays out, moving with the body, for this long before
            drawing back, s (arm-extended time 1.30 s minus the reach, 0.67; the hand is drawn
            back 0.37 s before the giver lets go, 1.0 s after the grasp: 0.63).
        pull_time: how long drawing the hand back takes, s: first straight toward the body at
            the height of the hold, by ``pull_distance`` (m, but no closer than
            ``CARRY_CLEARANCE`` to the pelvis axis), until the object is clear of the gripper,
            then down to the carry pose.
        grasp_radius: the hand grasps when its grip point is this close to the grasp point, m,
        grasp_speed: and moves relative to it slower than this, m/s (a hand closes on an object
            it has caught up with; the grip is then :mod:`handover_env.person.grip`'s spring).
        grasp_offset: the grasp point's distance from the object's centre along its axis, m, on
            the part the hand takes (``grasp_below``): the bottle's lower part, below the
            gripper's pads, or its top, above them.
        approach_distance, approach_height: the hand approaches the grasp point from this far
            toward the person and this far above it, closing in over the last ``close_time``, m.
        close_radius: recorded hand: the hand closes onto the object once the recorded grip point
            is this close to the object's centre, m (0.28: p95 of the recorded hand joint's
            distance from the object at the transfer; the ZED hand joint sits 0.17 m off the
            object there in the median recording).
        close_time: the closing motion's duration, s.
        carry_forward: the carry pose is this far forward of the hand's walking swing, m.
        present_time: static handover: time to raise the hand, s.
        present_reach: static handover: the raised hand takes the object once it is this close, m.
        reach_offset: switch, on by default: the take distance adds the person's own reach
            offset (drawn with the seed for a scripted walker, the recorded person's own for a
            replayed recording; :mod:`handover_env.person.take`). Off: every person reaches by
            the giver-dependent line alone.
        arm_yield: switch, on by default: touched by the robot, the reaching arm pushes at most
            as hard as a human arm and stops pushing after the tactile latency
            (:mod:`handover_env.person.arm_yield`). Off: the arm's welds drive it to its targets.
        avoid_gripper: switch, on by default: the hand that holds the object draws it out of the
            gripper by its open side (never deeper along the gripper's approach axis than at the
            grasp, and from the first step that sees the gripper open ``CLEAR_OF_GRIPPER``
            farther out; :func:`handover_env.person.hand_path.hand_kernel`). Off: the hand stays
            with the body for ``hold_time`` whatever the gripper does.
        grasp_below: switch, on by default: the modelled hand takes the object's lower part,
            ``grasp_offset`` below its centre and below the gripper's pads, approached from
            below, as the recorded receivers did (at the transfer their right wrist and hand
            joints were below the object's centre in all 427 calibration recordings, median
            -0.11 m, the elbow too, the forearm about level: ``handover-data grasp-height``,
            ``docs/calibration/grasp_height.md``), so the forearm stays below the fingers.
            Off: the top part, above the pads, approached from above, the forearm running down
            past the fingers. A recorded hand (``hand_mode="recorded"``) takes the part it
            comes from either way.
        recorded_elbow: switch, on by default: the reaching arm's elbow lies off the
            shoulder-wrist line in the direction the recorded receivers held it at the transfer,
            down and back (:data:`~handover_env.person.posing.ELBOW_POLE_RECORDED`,
            ``docs/calibration/grasp_height.md``). Off: down and out to the right
            (:data:`~handover_env.person.posing.ELBOW_POLE_OUT`), which swings the elbow of an
            arm folded to take an object close to the body out toward the robot, past the
            gripper.
        joint_damping: switch, off by default: every ball joint of the body carries the passive
            damping :data:`~handover_env.person.body_model.PASSIVE_JOINT_DAMPING` relative to
            its parent segment. Off: the body's damping is its welds', about its intended
            motion (damping ratio about 1); a joint damping relative to the parent resists
            the voluntary motion itself, which the targets' feed-forward does not make up for,
            and kept a folded, moving arm 4-5 cm off its target (docs/simulator.md).
    """

    reach_duration: float = 0.63
    reach_lead_time: float = 0.63
    comfort_fraction: float = 1.10
    min_speed_factor: float = 0.82
    slow_rate: float = 1.5
    give_up_behind: float = 0.35
    hold_time: float = 0.63
    pull_time: float = 0.5
    pull_distance: float = 0.2
    grasp_radius: float = 0.03
    grasp_speed: float = 0.2
    grasp_offset: float = 0.075
    approach_distance: float = 0.12
    approach_height: float = 0.04
    close_radius: float = 0.28
    close_time: float = 0.25
    carry_forward: float = 0.15
    present_time: float = 0.8
    present_reach: float = 0.15
    reach_offset: bool = True
    arm_yield: bool = True
    avoid_gripper: bool = True
    grasp_below: bool = True
    recorded_elbow: bool = True
    joint_damping: bool = False

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if name in SWITCHES:
                object.__setattr__(self, name, check_switch(name, value))
            else:
                object.__setattr__(self, name, check_setting(name, value))


def check_switch(name: str, value: object) -> bool:
    """``value`` if it is True or False (a person switch, :data:`SWITCHES`)."""
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"person setting {name} must be True or False, got {value!r}")
    return bool(value)


def switch_tokens(tokens: tuple[str, ...] | list[str]) -> dict[str, bool]:
    """The person switches named by command-line tokens: ``NAME`` or ``NAME=on`` switches one on,
    ``NAME=off`` off (any of :data:`SWITCHES`, each at most once); the rest keep their defaults.
    One ValueError names every bad token."""
    out: dict[str, bool] = {}
    bad = []
    for token in tokens:
        name, _, state = str(token).partition("=")
        if name not in SWITCHES or state not in ("", "on", "off") or name in out:
            bad.append(token)
            continue
        out[name] = state != "off"
    if bad:
        raise ValueError(f"--person {list(tokens)}: {bad} not understood; each of "
                         f"{list(SWITCHES)} at most once, as NAME, NAME=on or NAME=off")
    return out


def check_setting(name: str, value: object) -> float:
    """``value`` as a float if it is a valid person setting ``name`` (:data:`SETTING_RANGES`)."""
    lo, hi, unit, why = SETTING_RANGES[name]
    return checked_number(f"person setting {name}", value, lo, hi, unit, why)


def check_option(name: str, value: object, bounds: tuple[float, float], unit: str) -> float:
    """A numeric reset option as a float: a real number (not a bool), finite, within bounds."""
    lo, hi = bounds
    return checked_number(name, value, lo, hi, unit)


def person_config(person: object, miss_distance: float) -> ReceiverConfig:
    """The env's ``person=`` overrides as a :class:`ReceiverConfig` (``give_up_behind`` defaults
    to the env's ``miss_distance``).

    Raises:
        ValueError: ``person`` is not a dict, names an unknown setting, or a value is not a
            number within its range (:data:`SETTING_RANGES`); the message names the setting.
    """
    if person is None:
        person = {}
    if not isinstance(person, Mapping):
        raise ValueError(
            f"person must be a dict of ReceiverConfig settings, got {type(person).__name__}"
        )
    known = ReceiverConfig.__dataclass_fields__
    unknown = sorted(repr(k) for k in person if not isinstance(k, str) or k not in known)
    if unknown:
        raise ValueError(
            f"unknown person setting(s) {unknown}; see handover_env.person.settings.ReceiverConfig"
        )
    overrides = dict(person)
    if "give_up_behind" not in overrides:
        try:
            overrides["give_up_behind"] = check_setting("give_up_behind", miss_distance)
        except ValueError as exc:
            raise ValueError(f"miss_distance (the person's give_up_behind): {exc}") from None
    return ReceiverConfig(**overrides)
