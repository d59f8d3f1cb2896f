"""Sensor models of the paper's robot (issue 24): the ZED 2i body tracker and the UR5e wrist F/T.

* :class:`~handover_env.sensors.camera.Camera`: ``Camera(params).reset(rng)``, then
  ``frame(t, {"pelvis": xy, "hand": xyz}) -> Observation(points, tracked, t_capture)``.
* :class:`~handover_env.sensors.wrist_ft.WristFT`: ``WristFT(params).reset(rng, mass, com)``, then
  ``measure(force_world, specific_force_world, rotation, dt) -> force_world`` and ``zero()``.
* :func:`~handover_env.sensors.profiles.make_profile`: the "paper", "ideal" and "randomized"
  parameter sets (:class:`~handover_env.sensors.profiles.SensorProfile`), with checked overrides.

Sources of every number: docs/sensing.md.
"""

from handover_env.sensors.camera import Camera, Observation
from handover_env.sensors.profiles import (
    PROFILES,
    CameraParams,
    ControllerParams,
    SensorProfile,
    WristFTParams,
    make_profile,
)
from handover_env.sensors.wrist_ft import WristFT

__all__ = [
    "PROFILES",
    "Camera",
    "CameraParams",
    "ControllerParams",
    "Observation",
    "SensorProfile",
    "WristFT",
    "WristFTParams",
    "make_profile",
]
