"""handover_env: the open reference implementation of Learning-based Dynamic Robot-to-Human
Handover (Kim et al., ICRA 2025). Importing the package registers the envs (idempotently):

* ``handover_env/DynamicHandover-v0`` (the receiver keeps walking), TimeLimit 450 steps (15 s);
* ``handover_env/StaticHandover-v0`` (the receiver stops and raises a hand), 600 steps (20 s).

``gym.make("handover_env:handover_env/DynamicHandover-v0")`` imports this module first, so it
also works in fresh processes (vector-env workers).
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

#: The package version: the one string pyproject.toml reads (dynamic version), every result.json
#: records (software.handover_env) and CHANGELOG.md and CITATION.cff name.
__version__ = "0.1.0"

_ENVS = {
    "handover_env/DynamicHandover-v0": (
        "handover_env.envs.dynamic_handover_v0:DynamicHandoverEnv",
        450,
    ),
    "handover_env/StaticHandover-v0": (
        "handover_env.envs.static_handover_v0:StaticHandoverEnv",
        600,
    ),
}


def register_envs() -> None:
    """Register the env ids with Gymnasium; safe to call more than once."""
    for env_id, (entry_point, steps) in _ENVS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, max_episode_steps=steps)


register_envs()
