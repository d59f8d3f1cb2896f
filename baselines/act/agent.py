"""ACT (Action Chunking with Transformers) through LeRobot 0.4.x's own ``ACTPolicy``.

State-only ACT: no camera, no vision backbone, no pretrained weights, no network.

| ACT input / output | feature type | shape | content (:mod:`handover_env.data.features`) |
|---|---|---|---|
| ``observation.environment_state`` | ENV | (2 W,) | receiver base xy history (xy + offsets) |
| ``observation.state`` | STATE | (3,) | current giver xyz (robot TCP in the env) |
| ``action`` | ACTION | (3,) | giver xyz; the policy predicts a chunk of H=30 |

Training goes through LeRobot's machinery: the dataset is exported with
:func:`handover_env.data.lerobot_export.export_lerobot`, read back as a ``LeRobotDataset`` with
``delta_timestamps`` for the action chunk, normalised by ``make_act_pre_post_processors`` with
statistics (``get_feature_stats``) of the training episodes for all three features (ENV, STATE and
ACTION all MEAN_STD), and optimised with ``ACTPolicy.forward`` (L1 + KL loss) under AdamW with the
gradient clipping of LeRobot's ACT preset. ``fit_lerobot(..., episodes=...)`` trains on a subset of
an export's episodes (split and statistics from that subset only), so k-fold evaluations export
the whole dataset once (:mod:`handover_eval.act_folds`).

CPU cost (receiver-only default model, batch 64, one thread, 2-core AMD EPYC VM): a step is
~5.4 GFLOP of forward + backward, ~117 ms (8.6 steps/s). Besides the model itself, training
avoids: reading the export column by column (~80 s a fold, now one batch read), calling the
preprocessor per batch (the samples are normalised once, bitwise the same tensors), the
per-parameter
AdamW loop (``fused=True``) and most of ``torch.bernoulli_``'s dropout-mask cost
(:class:`DropoutMasks`, ``fast_dropout``). Before these the same loop ran at ~7 steps/s.

In an env the agent is a :class:`agents.predictive.PredictiveAgent` like the planner (same ready
pose, yaw rule and t_f of Theta), except for the ensembling: each new camera frame goes through
``ACTPolicy.select_action``, i.e. LeRobot's ``ACTTemporalEnsembler``
(``temporal_ensemble_coeff=0.01``, ``n_action_steps=1``), as the paper does. The returned current
action plus the ensembler's remaining future rows form the ensembled chunk from which the
target at t_f is read (:class:`EnsembledChunk`).

Model sizes:

* default (8000 steps train on one CPU core in ~16 min on the 875-episode set): ``dim_model=128``,
  ``n_heads=4``, ``dim_feedforward=512``, 2 encoder layers, 1 decoder layer, VAE with
  1 encoder layer and ``latent_dim=16``, dropout 0.1, ``kl_weight=10``.
* ``paper_scale=True`` (``--paper-scale``): LeRobot's/ACT's defaults, ``dim_model=512``,
  ``n_heads=8``, ``dim_feedforward=3200``, 4 encoder layers, 1 decoder layer, VAE with 4 encoder
  layers and ``latent_dim=32``.

Checkpoint format 2 keeps the model's fields as LeRobot's ``ACTConfig`` overrides (``policy``);
format-1 checkpoints (flat fields) still load (:meth:`ACTAgentConfig.from_legacy`), and the
evaluation caches key ACT checkpoints by that layout, so earlier ones are reused.

Checkpoint folder: ``config.json`` + ``model.safetensors`` (``ACTPolicy.save_pretrained``),
``policy_preprocessor*.json/.safetensors`` and ``policy_postprocessor*`` (the normalisation
statistics), ``handover_act.json`` (our config, features and training summary) and
``training_state/`` (last weights, optimizer, RNG and step) for ``--resume``. Each checkpoint is
written as one unit (:func:`baselines.checkpoint_io.staged_write`). Loading writes nothing (an
interrupted commit is refused, never finished; ``--resume`` finishes it) and validates every file
first (:mod:`baselines.act_files`: LeRobot's processor JSON can name any importable class, so it is
checked against an allow-list and never handed to LeRobot) and builds the policy and processors
from our own validated config.

Reproducibility: training runs under :func:`reproducible` (seeded Python, numpy and torch RNGs,
one torch thread, ``torch.use_deterministic_algorithms``), with data order and dropout masks drawn
from the seed and the step, so a seed gives bit-identical weights in any process
(``tests/test_act_determinism.py``), whatever torch thread count the caller set.
"""

from __future__ import annotations

import contextlib
import math
import os
import random
import tempfile
import time
import typing
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from handover_env.extras import missing_extra

try:
    import lerobot  # noqa: F401 - ACT is LeRobot's ACTPolicy
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None

from agents.predictive import ClosedLoopConfig
from baselines import act_files, trainer
from baselines.checkpoint_io import (
    CheckpointError,
    check_loadable,
    config_from_dict,
    expected_of,
    json_type_ok,
    load_tensors,
    staged_write,
    write_json,
)
from baselines.giver_conditioned import GiverConditionedAgent
from baselines.norm_bounds import feature_limits
from handover_env.config import HandoverParams
from handover_env.data.dataset import Episode, HandoverDataset
from handover_env.data.features import (
    ACTION,
    ACTION_DIM,
    OBS_ENV_STATE,
    OBS_STATE,
    STATE_DIM,
    FeatureSpec,
    encode_history,
    split_train_val,
    validate_giver,
)
from handover_env.envs.observation import ObsLayout

CHECKPOINT_TYPE = "act"
CHECKPOINT_FORMAT = 2
HANDOVER_JSON = "handover_act.json"
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
#: The gradient clip of format 1, fixed since (LeRobot's ACT optimiser preset).
LEGACY_GRAD_CLIP = 10.0
#: torch intra-op threads while ACT trains. Summation order, hence the last bits of every step,
#: depends on the thread count; one thread makes a seed reproducible in any process (and is also
#: the fast setting on the project's shared 2-core machine; parallelism comes from processes).
TRAIN_THREADS = 1
#: Config fields a resumed run may change (a longer run, another validation cadence or device).
RESUMABLE_CHANGES = frozenset({"steps", "eval_every", "device"})


def _settable_fields() -> dict[str, Any]:
    """{name: type hint} of the ``ACTConfig`` fields an :class:`ACTAgentConfig` may override."""
    from lerobot.policies.act.configuration_act import ACTConfig

    hints = typing.get_type_hints(ACTConfig)
    return {
        f.name: hints[f.name] for f in fields(ACTConfig) if f.init and f.name not in OWNED_FIELDS
    }


@contextlib.contextmanager
def reproducible(seed: int) -> Iterator[None]:
    """Seed Python, numpy and torch, use :data:`TRAIN_THREADS` threads and deterministic algorithms.

    The caller's thread count and deterministic-algorithms setting are restored on exit.
    """
    threads = torch.get_num_threads()
    deterministic = torch.are_deterministic_algorithms_enabled()
    warn_only = torch.is_deterministic_algorithms_warn_only_enabled()
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    torch.set_num_threads(TRAIN_THREADS)
    torch.use_deterministic_algorithms(True, warn_only=True)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
        torch.use_deterministic_algorithms(deterministic, warn_only=warn_only)


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
            from :class:`DropoutMasks` (same p and scaling, ~1/8 of the step time saved on one core)
            instead of ``torch.bernoulli_``. False trains with PyTorch's own dropout everywhere.
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
        """This config in the flat layout of checkpoint format 1 (before it wrapped ``ACTConfig``),
        or None if it sets an ``ACTConfig`` field that layout did not have.

        Evaluation caches key their ACT checkpoints by this layout (``handover_eval.methods``), so
        checkpoints trained before the change are found and reused.
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


# ---------------------------------------------------------------------- LeRobot data
def open_export(root: str | os.PathLike, repo_id: str, spec: FeatureSpec):
    """``LeRobotDataset(repo_id, root, delta_timestamps=...)`` after checking its features fit
    ``spec``."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from handover_env.data.lerobot_export import action_delta_timestamps, read_sidecar

    sidecar = read_sidecar(root)
    ds = LeRobotDataset(
        repo_id, root=root, delta_timestamps=action_delta_timestamps(spec.horizon, spec.rate_hz)
    )
    want = {OBS_ENV_STATE: (spec.env_dim,), OBS_STATE: (STATE_DIM,), ACTION: (ACTION_DIM,)}
    for key, shape in want.items():
        if key not in ds.features:
            raise ValueError(
                f"LeRobot dataset at {root} has no feature {key!r} (features: "
                f"{sorted(ds.features)})"
            )
        got = tuple(ds.features[key]["shape"])
        if got != shape:
            raise ValueError(
                f"LeRobot dataset at {root}: feature {key!r} has shape {got}, this ACT config "
                f"needs {shape} "
                f"(history W={spec.history}; the export used W={sidecar.get('history')})"
            )
    if int(ds.fps) != int(round(spec.rate_hz)):
        raise ValueError(f"LeRobot dataset at {root} is at {ds.fps} fps, expected {spec.rate_hz}")
    return ds, sidecar


def lerobot_samples(ds, episode_indices: np.ndarray) -> dict[str, torch.Tensor]:
    """Every frame of ``episode_indices`` as LeRobot training samples, vectorised.

    Reads the parquet columns once and applies ``ds.delta_indices`` exactly as
    ``LeRobotDataset.__getitem__`` does (indices clamped to the episode, ``action_is_pad`` outside
    it); ``tests/test_act.py`` checks the result equals ``ds[i]`` item by item. One pass through
    ``__getitem__`` costs ~2 ms per frame, too slow to repeat every step on 2 cores. The columns are
    read as one numpy batch: ``datasets``' lazy column objects convert row by row, which took ~80 s
    for the 100k frames of the public set.
    """
    cols = ds.hf_dataset.with_format("numpy")[
        :
    ]  # one batch read (~0.4 s); column access iterates rows (~80 s)
    env = np.asarray(cols[OBS_ENV_STATE], dtype=np.float32)
    state = np.asarray(cols[OBS_STATE], dtype=np.float32)
    action = np.asarray(cols[ACTION], dtype=np.float32)
    index = np.asarray(cols["index"], dtype=np.int64)
    if not np.array_equal(index, np.arange(index.size)):
        raise ValueError("LeRobot dataset rows are not in index order; re-export it")
    deltas = np.asarray(ds.delta_indices[ACTION], dtype=np.int64)
    out: dict[str, list[np.ndarray]] = {
        k: [] for k in (OBS_ENV_STATE, OBS_STATE, ACTION, "action_is_pad")
    }
    for e in np.asarray(episode_indices, dtype=np.int64):
        ep = ds.meta.episodes[int(e)]
        start, end = int(ep["dataset_from_index"]), int(ep["dataset_to_index"])
        rows = np.arange(start, end)
        q = rows[:, None] + deltas[None, :]
        out[OBS_ENV_STATE].append(env[rows])
        out[OBS_STATE].append(state[rows])
        out[ACTION].append(action[np.clip(q, start, end - 1)])
        out["action_is_pad"].append((q < start) | (q >= end))
    return {k: torch.as_tensor(np.concatenate(v)) for k, v in out.items()}


def normalise_samples(
    preprocessor, samples: dict[str, torch.Tensor], chunk: int = 32_768
) -> dict[str, torch.Tensor]:
    """``samples`` passed through LeRobot's ``preprocessor`` once, instead of once per batch.

    The pipeline (rename, batch dim, device, ``NormalizerProcessorStep``) is elementwise over rows,
    so normalising all rows up front and indexing a batch afterwards gives bitwise the same tensors
    as indexing first and normalising the batch (``tests/test_act.py`` checks it). ``chunk`` rows at
    a time bound the pipeline's temporaries.
    """
    n = int(next(iter(samples.values())).shape[0])
    parts = [
        preprocessor({k: v[i : i + chunk] for k, v in samples.items()})
        for i in range(0, max(n, 1), chunk)
    ]
    return {k: torch.cat([part[k] for part in parts]) if parts else samples[k] for k in samples}


def feature_stats(samples: dict[str, torch.Tensor]) -> dict[str, dict[str, np.ndarray]]:
    """LeRobot ``get_feature_stats`` of the training samples (action over its per-frame values)."""
    from lerobot.datasets.compute_stats import get_feature_stats

    per_frame_action = samples[ACTION][
        :, 0
    ].numpy()  # the action column itself, as LeRobot's stats.json
    return {
        OBS_ENV_STATE: get_feature_stats(samples[OBS_ENV_STATE].numpy(), axis=0, keepdims=False),
        OBS_STATE: get_feature_stats(samples[OBS_STATE].numpy(), axis=0, keepdims=False),
        ACTION: get_feature_stats(per_frame_action, axis=0, keepdims=False),
    }


def check_episodes(episodes: np.ndarray | None, n_export: int) -> np.ndarray:
    """Export episode indices to train on (all of them for None), validated: 1-D, unique, in
    range."""
    if episodes is None:
        return np.arange(n_export, dtype=np.int64)
    arr = np.asarray(episodes)
    if arr.ndim != 1 or (arr.size and not np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(
            f"episodes must be a 1-D array of export episode indices, got dtype {arr.dtype}, "
            f"shape {arr.shape}"
        )
    arr = arr.astype(np.int64)
    if arr.size < 2:
        raise ValueError(f"need at least 2 episodes for a train/validation split, got {arr.size}")
    if arr.min() < 0 or arr.max() >= n_export:
        raise ValueError(
            f"episode indices must lie in [0, {n_export - 1}] (the export has {n_export} episodes)"
        )
    if np.unique(arr).size != arr.size:
        raise ValueError("episode indices must be unique")
    return arr


def _split_from_export(
    sidecar: dict, val_fraction: float, seed: int, episodes: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The same stratified episode split as BC-MLP's, from the export's ID/OOD flags.

    With ``episodes`` (export indices) only those are split, in the given order, so training on
    ``episodes`` of a whole-dataset export splits exactly like training on an export of just those
    episodes. Returns export episode indices (train, val).
    """
    chosen = check_episodes(episodes, len(sidecar["source_id"]))
    stub = HandoverDataset(
        [
            Episode(
                np.zeros((2, 2)),
                np.zeros((2, 3)),
                np.zeros((2, 3)),
                np.tile([1.0, 0, 0, 0], (2, 1)),
                bool(sidecar["is_ood"][i]),
                sidecar["source_id"][i],
            )
            for i in chosen
        ]
    )
    train, val = split_train_val(stub, val_fraction, seed)
    return chosen[train], chosen[val]


# ---------------------------------------------------------------------- fast dropout masks
class DropoutMasks:
    """Bernoulli keep-masks for dropout, drawn from numpy's SFC64 and re-seeded every step.

    ``torch.nn.Dropout`` on CPU draws its mask with ``bernoulli_`` (one mt19937 draw per element,
    ~7.5 ms for the 1M-element feed-forward activations of a batch of 64): about a fifth of an ACT
    step on one core. This draws the same i.i.d. Bernoulli(1 - p) mask (keep if a uniform 32-bit
    word >= round(p 2^32), i.e. p exact to 2^-32) from SFC64's raw output at ~1 ns per element.
    Seeding from ``(seed, step)`` keeps training deterministic and resumable without extra state.
    """

    def __init__(self, seed: int) -> None:
        self.seed = int(seed) % 2**63
        self.reseed(0)

    def reseed(self, step: int) -> None:
        self._bits = np.random.SFC64(np.random.SeedSequence([self.seed, int(step)]))

    def noise(self, shape: torch.Size, p: float, dtype: torch.dtype) -> torch.Tensor:
        """Keep-mask scaled by 1/(1-p) (what ATen's dropout multiplies the input by)."""
        n = math.prod(shape)
        words = self._bits.random_raw((n + 1) // 2).view(np.uint32)[:n]
        threshold = np.uint32(min(round(p * 2.0**32), 2**32 - 1))
        np_dtype = np.float64 if dtype == torch.float64 else np.float32
        noise = np.multiply(words >= threshold, np_dtype(1.0 / (1.0 - p)), dtype=np_dtype)
        return torch.from_numpy(noise).view(shape).to(dtype)


class FastDropout(torch.nn.Dropout):
    """``nn.Dropout`` (same p, same train/eval behaviour) with its mask from
    :class:`DropoutMasks`."""

    def __init__(self, p: float, masks: DropoutMasks) -> None:
        super().__init__(p)
        self.masks = masks

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training or self.p == 0.0:
            return x
        return x * self.masks.noise(x.shape, self.p, x.dtype)


@contextlib.contextmanager
def fast_dropout(policy: torch.nn.Module, masks: DropoutMasks):
    """Swap every ``nn.Dropout`` module of ``policy`` for a :class:`FastDropout` while training.

    Only the dropout *modules* are swapped (the residual and feed-forward dropouts, ~87% of the
    dropped elements); ``nn.MultiheadAttention``'s internal attention dropout stays PyTorch's.
    The originals are put back on exit; dropout modules hold no weights, so checkpoints are
    unchanged.
    """
    swapped = []
    for parent in list(policy.modules()):
        for name, child in list(parent.named_children()):
            if type(child) is torch.nn.Dropout:
                setattr(parent, name, FastDropout(child.p, masks))
                swapped.append((parent, name, child))
    try:
        yield swapped
    finally:
        for parent, name, child in swapped:
            setattr(parent, name, child)


# ---------------------------------------------------------------------- the agent
class EnsembledChunk:
    """The ``TemporalEnsembler`` interface ``PredictiveAgent.act`` reads, over one ensembled chunk.

    LeRobot's ensembler already did the averaging inside ``select_action``; this holds its output
    (the current action and the ensembled future rows, in metres) and interpolates in it.
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.chunk: np.ndarray | None = None
        self.latest_start: int | None = None

    @property
    def empty(self) -> bool:
        return self.chunk is None

    def add(self, chunk: np.ndarray, start_frame: int) -> None:
        self.chunk, self.latest_start = np.asarray(chunk, dtype=np.float64), int(start_frame)

    def at(self, frame: float) -> np.ndarray | None:
        if self.chunk is None:
            return None
        k = min(max(float(frame) - self.latest_start, 0.0), float(self.chunk.shape[0] - 1))
        lo = int(math.floor(k))
        hi = min(lo + 1, self.chunk.shape[0] - 1)
        return (1.0 - (k - lo)) * self.chunk[lo] + (k - lo) * self.chunk[hi]


class ACTAgent(GiverConditionedAgent):
    """LeRobot's ``ACTPolicy`` behind the common agent interface.

    Args:
        config: model and training settings.
        params: Theta (t_f is used by ``act``); closed_loop, layout: see ``PredictiveAgent``.
    """

    # Rows per network call in open-loop evaluation: bounds the activations, and 256 rows run ~1.7x
    # faster than 1024 on one core (the decoder's activations stay in cache).
    predict_rows_per_batch = 256

    def __init__(
        self,
        config: ACTAgentConfig | None = None,
        params: HandoverParams | None = None,
        closed_loop: ClosedLoopConfig | None = None,
        layout: ObsLayout | None = None,
    ):
        from lerobot.policies.act.modeling_act import ACTPolicy
        from lerobot.policies.act.processor_act import make_act_pre_post_processors

        GiverConditionedAgent.__init__(self, params, closed_loop, layout)
        self.config = config or ACTAgentConfig()
        self.horizon = self.config.horizon
        torch.manual_seed(self.config.seed)
        self.policy = ACTPolicy(self.config.policy_config())
        self.policy.eval()
        self.preprocessor, self.postprocessor = make_act_pre_post_processors(
            self.policy.config, None
        )
        self.fitted = False
        self.train_log: dict = {}
        self._giver_now: np.ndarray | None = None

    # ------------------------------------------------------------------ training
    def fit(
        self,
        dataset: HandoverDataset,
        out_dir: str | os.PathLike | None = None,
        export_root: str | os.PathLike | None = None,
        resume: bool = False,
        progress: bool = False,
        steps: int | None = None,
        log: Callable[[str], None] | None = None,
        rebuild_export: bool = True,
    ) -> ACTAgent:
        """Export ``dataset`` to a LeRobotDataset (``export_root`` or a temp folder) and train on
        it.

        An existing export at ``export_root`` is reused only if it holds exactly ``dataset`` (its
        fingerprint, frames and the windows W, H). Otherwise it is rebuilt when ``rebuild_export``
        (only a folder that is an export of ours is replaced), or a CheckpointError says why not.
        """
        from handover_env.data.lerobot_export import export_lerobot, export_matches

        spec = self.config.spec
        with contextlib.ExitStack() as stack:
            if export_root is None:
                export_root = Path(stack.enter_context(tempfile.TemporaryDirectory())) / "lerobot"
            export_root = Path(export_root)
            if export_root.exists() or export_root.is_symlink():
                why = export_matches(export_root, dataset, spec.history, spec.horizon)
                if why is not None:
                    if not rebuild_export:
                        raise CheckpointError(
                            f"{why}; pass --overwrite to rebuild it, or another --export-root"
                        )
                    if log is not None:
                        log(f"rebuilding the LeRobot export: {why}")
                    export_lerobot(dataset, export_root, history=spec.history, horizon=spec.horizon,
                                   overwrite=True, progress=progress)
            else:
                export_lerobot(
                    dataset,
                    export_root,
                    history=spec.history,
                    horizon=spec.horizon,
                    progress=progress,
                )
            return self.fit_lerobot(export_root, out_dir=out_dir, resume=resume, progress=progress,
                                    steps=steps, log=log)

    def fit_lerobot(
        self,
        root: str | os.PathLike,
        repo_id: str = "local/handover",
        out_dir: str | os.PathLike | None = None,
        resume: bool = False,
        progress: bool = False,
        steps: int | None = None,
        log: Callable[[str], None] | None = None,
        episodes: np.ndarray | None = None,
    ) -> ACTAgent:
        """Train on a LeRobot export at ``root`` (see :mod:`handover_env.data.lerobot_export`).

        Args:
            root: the export folder.
            repo_id: its LeRobot repo id (local only).
            out_dir: checkpoint folder, rewritten every ``eval_every`` steps.
            resume: continue from ``out_dir/training_state``.
            progress: tqdm bar with the loss.
            steps: overrides ``config.steps``.
            log: called with one line per validation pass.
            episodes: train on these export episode indices only (default: all). The train /
                validation split and the normalisation statistics come from these episodes alone,
                exactly as if only they had been exported (the evaluation exports the whole dataset
                once and trains each fold on its training episodes).
        """
        cfg = self.config
        total_steps = cfg.steps if steps is None else int(steps)
        ds, sidecar = open_export(root, repo_id, cfg.spec)
        train_ep, val_ep = _split_from_export(sidecar, cfg.val_fraction, cfg.seed, episodes)
        train = lerobot_samples(ds, train_ep)
        val = lerobot_samples(ds, val_ep)
        stats = feature_stats(train)
        with reproducible(cfg.seed):
            return self._train(
                train,
                val,
                stats,
                sidecar,
                train_ep,
                val_ep,
                total_steps,
                out_dir,
                resume,
                progress,
                log,
            )

    def _train(
        self,
        train: dict[str, torch.Tensor],
        val: dict[str, torch.Tensor],
        stats: dict,
        sidecar: dict,
        train_ep: np.ndarray,
        val_ep: np.ndarray,
        total_steps: int,
        out_dir: str | os.PathLike | None,
        resume: bool,
        progress: bool,
        log: Callable[[str], None] | None,
    ) -> ACTAgent:
        """The optimisation loop of :meth:`fit_lerobot` (runs under :func:`reproducible`)."""
        from lerobot.policies.act.modeling_act import ACTPolicy
        from lerobot.policies.act.processor_act import make_act_pre_post_processors

        cfg = self.config
        policy_cfg = cfg.policy_config()
        self.policy = ACTPolicy(policy_cfg)
        self.preprocessor, self.postprocessor = make_act_pre_post_processors(
            self.policy.config, stats
        )
        train = normalise_samples(self.preprocessor, train)  # once, not per batch: same tensors
        val = normalise_samples(self.preprocessor, val)
        preset = policy_cfg.get_optimizer_preset()  # LeRobot's ACT optimiser: AdamW, grad clip 10
        opt = torch.optim.AdamW(
            self.policy.parameters(),
            lr=preset.lr,
            betas=preset.betas,
            eps=preset.eps,
            weight_decay=preset.weight_decay,
            fused=cfg.device == "cpu",
        )
        split = {"train": [sidecar["source_id"][i] for i in train_ep],
                 "val": [sidecar["source_id"][i] for i in val_ep]}
        state = trainer.new_state("step", split)
        best = trainer.clone_weights(self.policy)
        out = trainer.out_path(out_dir)
        if resume:
            if out is None:
                raise CheckpointError("resume needs the checkpoint folder (out_dir)")
            state, best = trainer.load_training_state(
                out,
                self.policy,
                opt,
                split=split,
                config=asdict(cfg),
                saved_config=lambda o: _read_handover_json(o)["config"],
                resumable=RESUMABLE_CHANGES,
                check_state=_check_state,
                rng=True,
            )

        n = train[ACTION].shape[0]
        per_epoch = max(1, n // cfg.batch_size)
        t_start = time.perf_counter() - state["wall_time_s"]
        report = trainer.TrainingProgress(
            "act",
            total_steps,
            state["step"],
            "step",
            progress,
            log,
            trainer.previous_log(out) if resume and out is not None else "",
        )
        running, count = 0.0, 0
        perm = None
        masks = DropoutMasks(cfg.seed)
        use_fast = cfg.fast_dropout and torch.device(cfg.device).type == "cpu"
        try:
            with fast_dropout(self.policy, masks) if use_fast else contextlib.nullcontext():
                while state["step"] < total_steps:
                    step = state["step"]
                    epoch, pos = divmod(step, per_epoch)
                    if (
                        perm is None or pos == 0
                    ):  # the permutation depends only on (seed, epoch): resumable
                        gen = torch.Generator().manual_seed(cfg.seed * 100_003 + epoch)
                        perm = torch.randperm(n, generator=gen)
                    idx = perm[pos * cfg.batch_size : (pos + 1) * cfg.batch_size]
                    self.policy.train()
                    masks.reseed(step)
                    loss, _ = self.policy.forward({k: v[idx] for k, v in train.items()})
                    if not torch.isfinite(loss):
                        raise FloatingPointError(
                            f"ACT training diverged at step {step + 1} (loss {float(loss)}); "
                            "check the "
                            f"data's coordinates and the learning rate"
                        )
                    opt.zero_grad(set_to_none=True)
                    loss.backward()
                    torch.nn.utils.clip_grad_norm_(self.policy.parameters(), preset.grad_clip_norm)
                    opt.step()
                    running += loss.item()
                    count += 1
                    state["step"] = step + 1
                    report.advance(1, running / count if count % 25 == 0 else None)
                    if state["step"] % cfg.eval_every == 0 or state["step"] == total_steps:
                        val_l1 = self._val_l1(val)
                        if trainer.record_validation(
                            state, "step", running / max(count, 1), val_l1
                        ):
                            best = trainer.clone_weights(self.policy)
                        running, count = 0.0, 0
                        state["wall_time_s"] = time.perf_counter() - t_start
                        report.validation(
                            state,
                            f"step {state['step']:6d}  train {state['train_loss'][-1]:.4f}  "
                            f"val L1 {val_l1:.4f}  best {state['best_val']:.4f} @ "
                            f"{state['best_step']}",
                        )
                        if out is not None:
                            trainer.save_checkpoint(
                                out,
                                lambda stage, best=best, state=state: self._write_model(
                                    stage, best, state
                                ),
                                self.policy,
                                opt,
                                state,
                                report,
                                rng=True,
                            )
        finally:
            report.close()
        self.policy.load_state_dict(best)
        self.policy.eval()
        self.fitted = True
        self.train_log = state
        return self

    @torch.no_grad()
    def _val_l1(self, val: dict[str, torch.Tensor], batch_size: int = 256) -> float:
        """Masked L1 of the normalised chunk (the reconstruction term of ACT's loss), zero latent.

        ``val`` is already normalised (:func:`normalise_samples`). Batches of 256 rows: a pass over
        a fold's ~10k validation frames takes ~3 s on one core, against ~5.5 s with 1024.
        """
        self.policy.eval()
        total, weight = 0.0, 0.0
        n = val[ACTION].shape[0]
        for i in range(0, n, batch_size):
            batch = {k: v[i : i + batch_size] for k, v in val.items()}
            pred = self.policy.predict_action_chunk(batch)
            valid = (~batch["action_is_pad"]).unsqueeze(-1).to(pred.dtype)
            total += float(((pred - batch[ACTION]).abs() * valid).sum())
            weight += float(valid.sum()) * ACTION_DIM
        return total / max(weight, 1.0)

    # ------------------------------------------------------------------ inference
    def _require_fitted(self) -> None:
        if not self.fitted:
            raise RuntimeError("ACTAgent is not trained: call fit(dataset) or ACTAgent.load(dir)")

    @torch.no_grad()
    def predict_batch(self, env_state: np.ndarray, state: np.ndarray) -> np.ndarray:
        """(B, H, 3) giver chunks for B feature rows (env_state (B, 2W), state (B, 3))."""
        self._require_fitted()
        env = torch.as_tensor(np.asarray(env_state, dtype=np.float32))
        st = torch.as_tensor(np.asarray(state, dtype=np.float32))
        if (
            env.ndim != 2
            or env.shape[1] != self.config.spec.env_dim
            or tuple(st.shape) != (env.shape[0], 3)
        ):
            raise ValueError(
                f"expected env_state (B, {self.config.spec.env_dim}) and state (B, 3), "
                f"got {tuple(env.shape)} and {tuple(st.shape)}"
            )
        batch = self.preprocessor({OBS_ENV_STATE: env, OBS_STATE: st})
        chunk = self.policy.predict_action_chunk(batch)
        return self.postprocessor(chunk).cpu().numpy().astype(np.float64)

    # ------------------------------------------------------------------ closed loop
    def reset(self) -> None:
        """New episode: PredictiveAgent state, LeRobot's ensembler (``policy.reset()``)."""
        super().reset()
        self.policy.reset()
        self._ensembler = EnsembledChunk()

    @torch.no_grad()
    def stream_predict(self) -> np.ndarray:
        """``select_action`` on the newest frame; returns the ensembled chunk (H, 3) in metres.

        Row 0 is the action ``select_action`` returns; rows 1.. are LeRobot's ensembled estimates of
        the next frames (``temporal_ensembler.ensembled_actions``), so t_f can be read from them.
        """
        self._require_fitted()
        env = torch.as_tensor(
            encode_history(np.asarray(self._history), self.config.history), dtype=torch.float32
        )
        state = validate_giver(self._giver_now) if self.config.use_giver_state else np.zeros(3)
        giver = torch.as_tensor(state, dtype=torch.float32)
        batch = self.preprocessor({OBS_ENV_STATE: env, OBS_STATE: giver})
        now = self.policy.select_action(batch)  # (1, 3), normalised
        rows = torch.cat([now[:, None], self.policy.temporal_ensembler.ensembled_actions], dim=1)
        return self.postprocessor(rows).numpy()[0].astype(np.float64)

    # ------------------------------------------------------------------ checkpoints
    def _write_model(self, out: Path, weights: dict | None, state: dict | None) -> None:
        """The policy, its processors and ``handover_act.json`` into the (staging) folder
        ``out``."""
        current = None
        if weights is not None:
            current = {k: v.detach().clone() for k, v in self.policy.state_dict().items()}
            self.policy.load_state_dict(weights)
        self.policy.save_pretrained(out)
        if current is not None:
            self.policy.load_state_dict(current)
        self.preprocessor.save_pretrained(out)
        self.postprocessor.save_pretrained(out)
        write_json(
            out / HANDOVER_JSON,
            trainer.checkpoint_json(CHECKPOINT_TYPE, CHECKPOINT_FORMAT, self.config, state),
        )

    def save(self, path: str | os.PathLike) -> Path:
        """Write the policy (``config.json``, ``model.safetensors``), processors and
        ``handover_act.json``, as a unit."""
        self._require_fitted()
        with staged_write(path) as stage:
            self._write_model(stage, None, self.train_log)
        return Path(path)

    @classmethod
    def load(cls, path: str | os.PathLike, device: str = "cpu", **closed_loop_kwargs) -> ACTAgent:
        """Load a checkpoint written by :meth:`save` or ``train.py act`` (local files only).

        Every file is validated before it is used (:mod:`baselines.act_files`); LeRobot never
        parses the checkpoint's JSON: the policy and the processors are built from our validated
        config and only their tensors are loaded. Any problem raises
        :class:`~baselines.checkpoint_io.CheckpointError` naming the file (and the processor step).
        ``closed_loop_kwargs`` (params, closed_loop, layout) go to ``PredictiveAgent``.
        """
        from lerobot.policies.act.modeling_act import ACTPolicy
        from lerobot.policies.act.processor_act import make_act_pre_post_processors

        path = check_loadable(path, (HANDOVER_JSON, "config.json", "model.safetensors",
                                     act_files.PREPROCESSOR_JSON, act_files.POSTPROCESSOR_JSON),
                              "ACT")  # writes nothing: an interrupted commit is refused
        saved = _read_handover_json(path)
        trained = ACTAgentConfig.from_dict(saved["config"], str(path / HANDOVER_JSON))
        cfg = ACTAgentConfig.from_dict(
            {**saved["config"], "device": device}, str(path / HANDOVER_JSON)
        )
        for name in (
            "config.json",
            "model.safetensors",
            act_files.PREPROCESSOR_JSON,
            act_files.POSTPROCESSOR_JSON,
        ):
            if not (path / name).is_file():
                raise CheckpointError(f"{path}: missing {name} (incomplete ACT checkpoint)")
        act_files.validate_config_json(path, trained.policy_config())
        saved_pre, saved_post = make_act_pre_post_processors(trained.policy_config(), None)
        pre_state = act_files.validate_processor_json(
            path, act_files.PREPROCESSOR_JSON, saved_pre, act_files.PREPROCESSOR_STEPS)
        post_state = act_files.validate_processor_json(
            path, act_files.POSTPROCESSOR_JSON, saved_post, act_files.POSTPROCESSOR_STEPS)
        shapes = {
            OBS_ENV_STATE: (cfg.spec.env_dim,),
            OBS_STATE: (STATE_DIM,),
            ACTION: (ACTION_DIM,),
        }
        state_files = {**pre_state, **post_state}
        check_loadable(path, [f.name for f in state_files.values()], "ACT")
        limits = feature_limits(cfg.spec.env_dim)
        stats = {i: act_files.load_stats(f, shapes, limits) for i, f in state_files.items()}
        pre_stats, post_stats = stats[3], stats[0]  # the normaliser and unnormaliser steps
        agent = cls.__new__(cls)
        GiverConditionedAgent.__init__(agent, **closed_loop_kwargs)
        agent.config, agent.horizon, agent._giver_now = cfg, cfg.horizon, None
        with torch.random.fork_rng(
            devices=[]
        ):  # the initial weights are overwritten: leave the caller's RNG be
            policy = ACTPolicy(cfg.policy_config())
        policy.load_state_dict(
            load_tensors(path / "model.safetensors", expected_of(policy.state_dict()))
        )
        agent.policy = policy.to(device)
        agent.preprocessor, agent.postprocessor = make_act_pre_post_processors(policy.config, None)
        try:
            agent.preprocessor.steps[3].load_state_dict(pre_stats)
            agent.postprocessor.steps[0].load_state_dict(post_stats)
        except (KeyError, RuntimeError, ValueError, TypeError) as exc:
            raise CheckpointError(f"{path}: normalisation statistics do not fit ({exc})") from None
        agent.policy.eval()
        agent.fitted = True
        agent.train_log = saved.get("training", {})
        return agent


def _check_state(state: object, source: Path) -> dict:
    """An ACT ``state.json`` whose fields have their types and agree with each other, or
    CheckpointError."""
    return trainer.check_state(state, source, "step")


def _read_handover_json(path: Path) -> dict:
    """``handover_act.json``, validated: type, format, a complete config and matching features."""
    return trainer.read_checkpoint_json(
        path, HANDOVER_JSON, CHECKPOINT_TYPE, CHECKPOINT_FORMAT, ACTAgentConfig, "ACT",
        upgrades={1: ACTAgentConfig.from_legacy},
    )
