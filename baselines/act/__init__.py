"""ACT (Action Chunking with Transformers) through LeRobot 0.4.x's own ``ACTPolicy``.

One module per role, after LeRobot's ``policies/act/{configuration_act,modeling_act,
processor_act}.py``:

| module | role |
|---|---|
| :mod:`baselines.act.config` | :class:`ACTAgentConfig` (LeRobot's ``ACTConfig`` plus what the agent adds) and the flat layout of checkpoint format 1 |
| :mod:`baselines.act.data` | the LeRobot export, its training samples, their statistics and normalisation, the episode split |
| :mod:`baselines.act.dropout` | dropout masks drawn from numpy's SFC64 for CPU training |
| :mod:`baselines.act.agent` | :class:`ACTAgent`: training (its step and validation functions; the loop is :func:`baselines.trainer.run`), inference in an env, checkpoints |
| :mod:`baselines.act.files` | validation of a checkpoint's LeRobot files before anything in them is used |

The public names of these modules are importable from here (``from baselines.act import
ACTAgent``), as from ``lerobot.policies.act``.
"""  # noqa: E501 - the table's rows cannot wrap

from baselines.act.agent import (
    CHECKPOINT_FORMAT,
    CHECKPOINT_TYPE,
    HANDOVER_JSON,
    RESUMABLE_CHANGES,
    TRAIN_THREADS,
    ACTAgent,
    EnsembledChunk,
    reproducible,
)
from baselines.act.config import (
    ACT_DEFAULTS,
    CPU_SCALE,
    LEGACY_GRAD_CLIP,
    LEGACY_MODEL_FIELDS,
    LEGACY_TYPES,
    OWNED_FIELDS,
    ACTAgentConfig,
)
from baselines.act.data import (
    check_episodes,
    feature_stats,
    lerobot_samples,
    normalise_samples,
    open_export,
    prepared_export,
    split_from_export,
    training_samples,
)
from baselines.act.dropout import DropoutMasks, FastDropout, fast_dropout

__all__ = [
    "ACT_DEFAULTS",
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_TYPE",
    "CPU_SCALE",
    "HANDOVER_JSON",
    "LEGACY_GRAD_CLIP",
    "LEGACY_MODEL_FIELDS",
    "LEGACY_TYPES",
    "OWNED_FIELDS",
    "RESUMABLE_CHANGES",
    "TRAIN_THREADS",
    "ACTAgent",
    "ACTAgentConfig",
    "DropoutMasks",
    "EnsembledChunk",
    "FastDropout",
    "check_episodes",
    "fast_dropout",
    "feature_stats",
    "lerobot_samples",
    "normalise_samples",
    "open_export",
    "prepared_export",
    "reproducible",
    "split_from_export",
    "training_samples",
]
