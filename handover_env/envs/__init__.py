"""The handover envs, one module per env and version."""

from handover_env.envs.dynamic_handover_v0 import DynamicHandoverEnv
from handover_env.envs.observation import ObsLayout
from handover_env.envs.static_handover_v0 import StaticHandoverEnv

__all__ = ["DynamicHandoverEnv", "ObsLayout", "StaticHandoverEnv"]
