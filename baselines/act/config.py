"""Configuration of the ACT baseline: LeRobot's ``ACTConfig`` plus what the agent adds, and the
flat layout of checkpoint format 1.

:class:`ACTAgentConfig` keeps the model's fields as ``ACTConfig`` overrides (``policy``) and builds
LeRobot's own config from them (:meth:`ACTAgentConfig.policy_config`). Model sizes:

* default (CPU-sized, :data:`CPU_SCALE`): ``dim_model=128``, ``n_heads=4``,
  ``dim_feedforward=512``, 2 encoder layers, 1 decoder layer, VAE with 1 encoder layer and
  ``latent_dim=16``, dropout 0.1, ``kl_weight=10``.
* ``paper_scale=True`` (``--paper-scale``): LeRobot's/ACT's defaults, ``dim_model=512``,
  ``n_heads=8``, ``dim_feedforward=3200``, 4 encoder layers, 1 decoder layer, VAE with 4 encoder
  layers and ``latent_dim=32``.

Checkpoint format 2 stores this config; a format-1 checkpoint stores the flat fields of
:data:`LEGACY_TYPES` and is read through :meth:`ACTAgentConfig.from_legacy`.
:meth:`ACTAgentConfig.legacy_dict` gives a config in that flat layout, the key the evaluation
caches file ACT checkpoints under.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from baselines.checkpoint_io import CheckpointError
from baselines.config_json import config_from_dict, json_type_ok
from handover_env.data.features import (
    ACTION,
    ACTION_DIM,
    OBS_ENV_STATE,
    OBS_STATE,
    STATE_DIM,
    FeatureSpec,
)

#: The CPU-sized model: LeRobot ``ACTConfig`` fields set unless ``paper_scale`` (which keeps
#: ACTConfig's own sizes, the paper's: dim 512, 8 heads, ffn 3200, 4 encoder layers, VAE 4,
#: latent 32).
CPU_SCALE: dict[str, int] = dict(
    dim_model=128, n_heads=4, dim_feedforward=512, n_encoder_layers=2, n_decoder_layers=1,
    n_vae_encoder_layers=1, latent_dim=16,
)
#: ``ACTConfig`` fields this baseline sets differently from LeRobot's defaults, whatever the size:
#: a higher learning rate for the small state-only model, and the paper's temporal ensembling.
ACT_DEFAULTS: dict[str, Any] = dict(optimizer_lr=1e-4, temporal_ensemble_coeff=0.01)
#: ``ACTConfig`` fields the agent owns (features, chunking, normalisation, device, no backbone
#: weights, no hub): they follow from ``history``, ``horizon``, ``use_giver_state`` and ``device``.
OWNED_FIELDS = frozenset(
    {
        "input_features",
        "output_features",
        "normalization_mapping",
        "chunk_size",
        "n_action_steps",
        "n_obs_steps",
        "device",
        "use_amp",
        "push_to_hub",
        "repo_id",
        "private",
        "tags",
        "license",
        "pretrained_path",
        "pretrained_backbone_weights",
        "vision_backbone",
        "replace_final_stride_with_dilation",
        "optimizer_lr_backbone",
        "use_peft",
    }
)
#: Checkpoint format 1 (flat config fields) -> ``ACTConfig`` field of this format's ``policy``.
LEGACY_MODEL_FIELDS = {
    "dim_model": "dim_model", "n_heads": "n_heads", "dim_feedforward": "dim_feedforward",
    "n_encoder_layers": "n_encoder_layers", "n_decoder_layers": "n_decoder_layers",
    "use_vae": "use_vae", "latent_dim": "latent_dim",
    "n_vae_encoder_layers": "n_vae_encoder_layers",
    "kl_weight": "kl_weight", "dropout": "dropout", "lr": "optimizer_lr",
    "weight_decay": "optimizer_weight_decay", "temporal_ensemble_coeff": "temporal_ensemble_coeff",
}
#: Every field of a format-1 config and its type.
LEGACY_TYPES: dict[str, type] = {
    "history": int, "horizon": int, "dim_model": int, "n_heads": int, "dim_feedforward": int,
    "n_encoder_layers": int, "n_decoder_layers": int, "use_vae": bool, "latent_dim": int,
    "n_vae_encoder_layers": int, "kl_weight": float, "dropout": float, "paper_scale": bool,
    "lr": float, "weight_decay": float, "grad_clip_norm": float, "batch_size": int, "steps": int,
    "eval_every": int, "val_fraction": float, "seed": int, "device": str,
    "temporal_ensemble_coeff": float, "use_giver_state": bool, "fast_dropout": bool,
}
#: The gradient clip a format-1 config holds (LeRobot's ACT optimiser preset).
LEGACY_GRAD_CLIP = 10.0


def _settable_fields() -> dict[str, Any]:
    """{name: type hint} of the ``ACTConfig`` fields an :class:`ACTAgentConfig` may override."""
    from lerobot.policies.act.configuration_act import ACTConfig

    hints = typing.get_type_hints(ACTConfig)
    return {
        f.name: hints[f.name] for f in fields(ACTConfig) if f.init and f.name not in OWNED_FIELDS
    }


@dataclass
class ACTAgentConfig:
    """Configuration of the ACT baseline: LeRobot's ``ACTConfig`` plus what the agent adds.

    The model is LeRobot's own ``ACTConfig`` (:meth:`policy_config`): its defaults, then
    :data:`ACT_DEFAULTS`, then :data:`CPU_SCALE` unless ``paper_scale``, then ``policy``. The
    optimiser is its ``get_optimizer_preset()`` (AdamW, ``optimizer_lr``,
    ``optimizer_weight_decay``, gradient clip 10).

    Args:
        history: W, frames of receiver history in ``observation.environment_state``.
        horizon: H, ACT's ``chunk_size`` (30 = 1 s, the paper's chunk).
        paper_scale: keep ``ACTConfig``'s own (the paper's) model size instead of :data:`CPU_SCALE`.
        policy: ``ACTConfig`` fields to override, e.g. ``{"dim_model": 256, "use_vae": False,
            "optimizer_lr": 3e-4, "kl_weight": 10.0}``; the fields the agent owns
            (:data:`OWNED_FIELDS`) cannot be set, and every value must have its field's type.
        batch_size: samples per step.
        steps: optimisation steps.
        eval_every: steps between validation passes (and checkpoints).
        val_fraction: fraction of episodes held out for validation (best checkpoint kept).
        seed: seeds initialisation, sampling and the split.
        device: torch device.
        use_giver_state: also give ACT ``observation.state`` (the current giver/robot xyz) as an
            input feature. Off by default: the receiver history alone, exactly what the planner
            sees and the input that works in the env (the batch still carries the key because
            LeRobot's ``ACT.forward`` reads its device).
        fast_dropout: during CPU training, draw the masks of the policy's ``nn.Dropout`` modules
            from :class:`~baselines.act.dropout.DropoutMasks` (same p and scaling) instead of
            ``torch.bernoulli_``. False trains with PyTorch's own dropout everywhere.
    """

    history: int = 10
    horizon: int = 30
    paper_scale: bool = False
    policy: dict[str, Any] = field(default_factory=dict)
    batch_size: int = 64
    steps: int = 8_000
    eval_every: int = 1_000
    val_fraction: float = 0.1
    seed: int = 0
    device: str = "cpu"
    use_giver_state: bool = False
    fast_dropout: bool = True

    def __post_init__(self) -> None:
        FeatureSpec(history=self.history, horizon=self.horizon)
        if not isinstance(self.policy, dict):
            raise ValueError(
                f"policy must be a dict of ACTConfig fields, got {type(self.policy).__name__}"
            )
        settable = _settable_fields()
        for key, value in self.policy.items():
            if key not in settable:
                why = "set by the agent" if key in OWNED_FIELDS else "not an ACTConfig field"
                raise ValueError(f"policy[{key!r}]: {why}")
            if not json_type_ok(value, settable[key]):
                raise ValueError(f"policy[{key!r}] = {value!r} is not a {settable[key]}")
        model = self.model()
        for name in (
            "dim_model",
            "n_heads",
            "dim_feedforward",
            "n_encoder_layers",
            "n_decoder_layers",
            "latent_dim",
            "n_vae_encoder_layers",
        ):
            if model[name] < 1:
                raise ValueError(f"{name} must be a positive integer, got {model[name]!r}")
        for name in ("batch_size", "steps", "eval_every"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if model["dim_model"] % model["n_heads"]:
            raise ValueError(
                f"dim_model ({model['dim_model']}) must be divisible by n_heads "
                f"({model['n_heads']})"
            )
        if (
            model["optimizer_lr"] <= 0
            or model["optimizer_weight_decay"] < 0
            or model["kl_weight"] < 0
        ):
            raise ValueError(
                "optimizer_lr must be positive, optimizer_weight_decay and kl_weight >= 0"
            )
        if not 0.0 <= model["dropout"] < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {model['dropout']}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")

    @property
    def spec(self) -> FeatureSpec:
        return FeatureSpec(history=self.history, horizon=self.horizon)

    def model(self) -> dict[str, Any]:
        """Every settable ``ACTConfig`` field as :meth:`policy_config` resolves it."""
        from lerobot.policies.act.configuration_act import ACTConfig

        defaults = {
            f.name: getattr(ACTConfig, f.name)
            for f in fields(ACTConfig)
            if f.name in _settable_fields()
            and not callable(getattr(ACTConfig, f.name, None))
            and hasattr(ACTConfig, f.name)
        }
        return {
            **defaults,
            **ACT_DEFAULTS,
            **({} if self.paper_scale else CPU_SCALE),
            **self.policy,
        }

    def policy_config(self):
        """LeRobot's ``ACTConfig`` for this agent (state-only, no backbone weights, no hub)."""
        from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature
        from lerobot.policies.act.configuration_act import ACTConfig

        return ACTConfig(
            input_features={
                OBS_ENV_STATE: PolicyFeature(type=FeatureType.ENV, shape=(self.spec.env_dim,)),
                **({OBS_STATE: PolicyFeature(type=FeatureType.STATE, shape=(STATE_DIM,))}
                   if self.use_giver_state else {}),
            },
            output_features={ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(ACTION_DIM,))},
            normalization_mapping={
                "VISUAL": NormalizationMode.MEAN_STD,
                "ENV": NormalizationMode.MEAN_STD,
                "STATE": NormalizationMode.MEAN_STD,
                "ACTION": NormalizationMode.MEAN_STD,
            },
            chunk_size=self.horizon,
            n_action_steps=1,
            pretrained_backbone_weights=None,
            device=self.device,
            push_to_hub=False,
            **{**ACT_DEFAULTS, **({} if self.paper_scale else CPU_SCALE), **self.policy},
        )

    def legacy_dict(self) -> dict[str, Any] | None:
        """This config in the flat layout of checkpoint format 1 (fields of :data:`LEGACY_TYPES`),
        or None if it sets an ``ACTConfig`` field that layout does not have.

        Evaluation caches key their ACT checkpoints by this layout (``handover_eval.methods``), so
        a cached checkpoint of either format is found and reused.
        """
        if not set(self.policy) <= set(LEGACY_MODEL_FIELDS.values()):
            return None
        model = self.model()
        d: dict[str, Any] = {"history": self.history, "horizon": self.horizon}
        for old, new in LEGACY_MODEL_FIELDS.items():
            value = model[new]
            d[old] = float(value) if LEGACY_TYPES[old] is float else value
        d["grad_clip_norm"] = LEGACY_GRAD_CLIP
        for name in ("paper_scale", "batch_size", "steps", "eval_every", "val_fraction", "seed",
                     "device", "use_giver_state", "fast_dropout"):
            d[name] = getattr(self, name)
        return d

    @classmethod
    def from_legacy(cls, d: Any, source: str = "config") -> dict[str, Any]:
        """A checkpoint-format-1 config (flat fields) as this format's config dict."""
        if not isinstance(d, dict) or set(d) != set(LEGACY_TYPES):
            raise CheckpointError(f"{source}: not a format-1 ACT config")
        for name, kind in LEGACY_TYPES.items():
            if not json_type_ok(d[name], kind):
                raise CheckpointError(
                    f"{source}: config field {name} = {d[name]!r} is not a {kind.__name__}"
                )
        if d["grad_clip_norm"] != LEGACY_GRAD_CLIP:
            raise CheckpointError(
                f"{source}: grad_clip_norm {d['grad_clip_norm']} (LeRobot's preset is 10)"
            )
        base = cls(paper_scale=d["paper_scale"]).model()
        policy = {new: d[old] for old, new in LEGACY_MODEL_FIELDS.items() if d[old] != base[new]}
        own = {k: d[k] for k in ("history", "horizon", "paper_scale", "batch_size", "steps",
                                 "eval_every", "val_fraction", "seed", "device", "use_giver_state",
                                 "fast_dropout")}
        return {**own, "policy": policy}

    @classmethod
    def from_dict(cls, d: dict, source: str = "config") -> ACTAgentConfig:
        """From a checkpoint's JSON: every field present and of its type (see
        ``config_from_dict``)."""
        return config_from_dict(cls, d, source)
