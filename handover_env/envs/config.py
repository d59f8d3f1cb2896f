"""What a handover env is built from: :class:`EnvConfig`, validated once.

``gym.make("handover_env/DynamicHandover-v0", sensing="ideal", params=HandoverParams(...))``
and ``DynamicHandoverEnv(config=EnvConfig(...))`` build the same env: the keywords of
``gym.make`` are the fields of :class:`EnvConfig` (:meth:`EnvConfig.from_keywords`). Θ is one
field, ``params`` (a :class:`~handover_env.config.HandoverParams` or a dict of its fields); for
``gym.make`` users its four fields also work as loose keywords (``stiffness``, ``damping``,
``forecast_time``, ``release_force``), but not beside ``params``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout
from handover_env.envs.tasks.base import HandoverReward, HandoverTask
from handover_env.person.receiver import CAMERA_RATE
from handover_env.person.settings import ReceiverConfig, person_config
from handover_env.robot.scene import SceneConfig
from handover_env.sensors import SensorProfile, make_profile
from handover_env.sensors.profiles import sensing_settings

#: Θ's fields, which ``gym.make`` also takes as loose keywords (instead of ``params``).
THETA_KEYWORDS: tuple[str, ...] = tuple(f.name for f in fields(HandoverParams))
RECEIVERS = ("id", "ood")


@dataclass(frozen=True)
class EnvConfig:
    """The settings of a handover env (its Arguments table), checked in ``__post_init__``.

    Args:
        params: Θ (paper Sec. IV-B; default the paper's Θ̂ = K 114.3, B 17.1, t_f 0.14, f_r 7.1),
            a :class:`~handover_env.config.HandoverParams` or a dict of its fields. The env reads
            its :data:`~handover_env.config.ROBOT_FIELDS` (K and B in the impedance controller,
            Eq. 1; f_r for the release); t_f is the agent's.
        safety_force: N, the pull on a held object that ends an episode as ``unsafe_force``
            (ISO/TS 15066 quasi-static hand limit).
        history: W, camera frames of receiver history in each observation (>= 2).
        obs_noise: camera override, m: white noise on both keypoints (None: the profile's).
        obs_latency: camera override, whole frames of latency (None: the profile's).
        default_receiver: ``"id"`` or ``"ood"``, the receiver when ``reset()`` names none.
        stabilisation_delay: s the static robot waits after detecting the hand.
        object_mass: kg, the handed-over bottle.
        miss_distance: m behind the shoulder at which an unheld bottle is walked past.
        force_filter_tau: wrist override: the force filter's time constant, s (None: the
            profile's).
        width, height, camera: the rendered image, pixels, and the MuJoCo camera.
        person: :class:`~handover_env.person.settings.ReceiverConfig` overrides.
        task: a :class:`~handover_env.envs.tasks.base.HandoverTask` instead of the env's own.
        reward: the default task's :class:`~handover_env.envs.tasks.base.HandoverReward` (or a
            dict of its fields); not beside ``task``.
        sensing: the sensor profile, ``"paper"``, ``"ideal"`` or ``"randomized"``.
        sensors: ``{"camera": {...}, "wrist": {...}, "controller": {...}}`` field overrides.

    The checked forms are kept beside the fields: ``sensor_overrides`` (every override, the
    camera / wrist keywords included), ``receiver`` (the person's settings, ``give_up_behind``
    defaulting to ``miss_distance``), ``scene`` and ``layout`` (the observation's).
    """

    params: HandoverParams | Mapping[str, float] = field(default_factory=HandoverParams)
    safety_force: float = 140.0
    history: int = 30
    obs_noise: float | None = None
    obs_latency: int | None = None
    default_receiver: str = "id"
    stabilisation_delay: float = 2.0
    object_mass: float = 0.4
    miss_distance: float = 0.35
    force_filter_tau: float | None = None
    width: int = 640
    height: int = 480
    camera: str = "overview"
    person: Mapping[str, float | bool] | None = None
    task: HandoverTask | None = None
    reward: HandoverReward | Mapping[str, float] | None = None
    sensing: str = "paper"
    sensors: Mapping[str, Mapping[str, float]] | None = None
    sensor_overrides: dict[str, dict[str, object]] = field(init=False, repr=False, compare=False)
    receiver: ReceiverConfig = field(init=False, repr=False, compare=False)
    scene: SceneConfig = field(init=False, repr=False, compare=False)
    layout: ObsLayout = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.default_receiver not in RECEIVERS:
            raise ValueError(
                f"default_receiver must be 'id' or 'ood', got {self.default_receiver!r}"
            )
        for name in ("safety_force", "stabilisation_delay", "miss_distance"):
            v = getattr(self, name)
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
            self._set(name, float(v))
        sensing, overrides = sensing_settings(
            self.sensing, self.sensors, self.obs_noise, self.obs_latency, self.force_filter_tau
        )
        self._set("sensor_overrides", overrides)
        rate = self.sensor_profile().camera.rate_hz
        if rate != CAMERA_RATE:
            raise ValueError(
                f"camera rate_hz must be the env's {CAMERA_RATE:g} Hz step, got {rate:g}"
            )
        if isinstance(self.history, bool) or int(self.history) != self.history:
            raise ValueError(f"history must be a whole number of frames, got {self.history!r}")
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v <= 0:
                raise ValueError(f"{name} must be a positive whole number of pixels, got {v!r}")
            self._set(name, int(v))
        self._set("params", self._theta(self.params))
        self._set("reward", self._reward(self.task, self.reward))
        self._set("scene", SceneConfig(object_mass=self.object_mass))
        self._set("history", int(self.history))
        self._set("layout", ObsLayout(history=self.history))
        self._set("receiver", person_config(self.person, miss_distance=self.miss_distance))

    def _set(self, name: str, value: object) -> None:
        object.__setattr__(self, name, value)

    @staticmethod
    def _theta(params: object) -> HandoverParams:
        if isinstance(params, Mapping):
            return HandoverParams(**params)
        if not isinstance(params, HandoverParams):
            raise ValueError(
                f"params must be a HandoverParams or a dict of its fields, got "
                f"{type(params).__name__}"
            )
        return params

    @staticmethod
    def _reward(task: object, reward: object) -> HandoverReward | None:
        if task is not None and reward is not None:
            raise ValueError(
                "pass the reward weights to the task (task=...(reward=...)) or reward=, not both"
            )
        if isinstance(reward, Mapping):
            reward = HandoverReward(**reward)
        if reward is not None and not isinstance(reward, HandoverReward):
            raise ValueError(
                "reward must be a HandoverReward or a dict of its fields, got "
                f"{type(reward).__name__}"
            )
        if task is not None and not isinstance(task, HandoverTask):
            raise ValueError(f"task must be a HandoverTask, got {type(task).__name__}")
        return reward

    def sensor_profile(self) -> SensorProfile:
        """The profile the env is built with: ``sensing``'s with the overrides (``"randomized"``
        starts from ``"paper"``'s and is drawn again at every reset)."""
        name = "paper" if self.sensing == "randomized" else self.sensing
        return make_profile(name, self.sensor_overrides)

    @classmethod
    def from_keywords(cls, **keywords: Any) -> EnvConfig:
        """The config of ``gym.make``'s keywords: the fields, with Θ as ``params`` or as its
        four loose keywords (not both).

        Raises:
            TypeError: a keyword that is no field (naming it).
            ValueError: Θ given both ways, or a value out of range (naming it).
        """
        known = {f.name for f in fields(cls) if f.init}
        unknown = sorted(k for k in keywords if k not in known and k not in THETA_KEYWORDS)
        if unknown:
            raise TypeError(f"unknown env argument(s) {unknown}; known: {sorted(known)} and "
                            f"Θ's {list(THETA_KEYWORDS)}")
        theta = {k: keywords.pop(k) for k in THETA_KEYWORDS if k in keywords}
        if theta:
            if keywords.get("params") is not None:
                raise ValueError(
                    f"pass Θ as params= or as {list(theta)} (loose keywords), not both"
                )
            keywords["params"] = HandoverParams(**theta)
        return cls(**keywords)

    @classmethod
    def of(cls, config: EnvConfig | None, **keywords: Any) -> EnvConfig:
        """``config`` itself, or the config of ``keywords`` (:meth:`from_keywords`); not both."""
        if config is None:
            return cls.from_keywords(**keywords)
        if not isinstance(config, EnvConfig):
            raise ValueError(f"config must be an EnvConfig, got {type(config).__name__}")
        if keywords:
            raise ValueError(
                f"pass the env's settings as config= or as keywords ({sorted(keywords)}), not both"
            )
        return config
