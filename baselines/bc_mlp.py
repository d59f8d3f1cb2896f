"""BC-MLP: behaviour cloning with a multi-layer perceptron (the paper's Table I baseline).

A torch MLP maps the shared baseline features of one frame (:mod:`handover_env.data.features`:
the W-frame receiver base-xy history and the current giver xyz) to the giver xyz chunk of the next
H = 30 frames. Inputs and outputs are standardised with mean/std statistics of the training frames,
kept as buffers of the module so they are saved with the weights (``model.safetensors``). Training
uses a masked MSE on the standardised chunk (rows past an episode end are masked), Adam, and early
stopping on a validation split of whole episodes (stratified by ID/OOD). Everything is seeded and
deterministic on CPU.

Checkpoint folder (``save``/``load``):

* ``config.json``        -- ``{"type": "bc_mlp", "format": 1, "config": BCMLPConfig fields, ...}``
* ``model.safetensors``  -- best weights and the normalisation statistics
* ``training_state/``    -- last weights, optimizer state (LeRobot's safetensors format) and
  ``state.json`` (epoch, best validation loss, patience counter, loss curves, split) for resuming
* ``train_log.jsonl``   -- one JSON line per epoch (losses, best so far, wall time)

The training loop is the shared :func:`baselines.trainer.run` (epochs, early stopping, best
weights, checkpoints, resume, progress); this module gives it one epoch's batches and the
validation loss. Every checkpoint is written as one unit, and :meth:`BCMLPAgent.load` /
``--resume`` validate every file before using it: all config fields present and of their JSON
type, weights of the model's shapes and dtypes, finite, normalisation statistics within what the
data can produce (:mod:`baselines.norm_bounds`), a ``state.json`` consistent with its loss curves.
Loading writes nothing (an interrupted commit is refused, never finished: ``--resume`` finishes
it). Plain torch: no LeRobot import.

In an env (``reset``/``act``) it is a :class:`agents.predictive.PredictiveAgent`, exactly like the
planner: one chunk per new camera frame, ACT-style temporal ensembling, the target at t_f of Theta,
the same ready pose and yaw rule. The giver state it conditions on is the robot's ``ee_pos``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from handover_env.extras import missing_extra

try:
    import torch
    from safetensors.torch import save_file
    from torch import nn
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None

from agents.predictive import ClosedLoopConfig
from baselines import checkpoint_meta, trainer
from baselines.checkpoint_io import (
    check_loadable,
    expected_of,
    load_tensors,
    staged_write,
    write_json,
)
from baselines.config_json import config_from_dict
from baselines.giver_conditioned import GiverConditionedAgent
from baselines.norm_bounds import MIN_STD, check_stat, feature_limits
from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_env.data.features import (
    ACTION,
    OBS_ENV_STATE,
    FeatureSpec,
    FrameArrays,
    dataset_frames,
    split_train_val,
)
from handover_env.envs.observation import ObsLayout

CHECKPOINT_TYPE = "bc_mlp"
CHECKPOINT_FORMAT = 1
#: Config fields a resumed run may change: it can be extended (more epochs, more patience) or
#: moved to another device; everything else must match the checkpoint.
RESUMABLE_CHANGES = frozenset({"max_epochs", "patience", "device"})


@dataclass
class BCMLPConfig:
    """Configuration of the BC-MLP baseline.

    Args:
        history: W, frames of receiver history in the input (see :mod:`handover_env.data.features`).
        horizon: H, frames of future giver xyz predicted (30 = 1 s, the paper's chunk).
        hidden: widths of the hidden layers.
        dropout: dropout after each hidden layer (0 keeps training fully deterministic).
        lr: Adam learning rate.
        weight_decay: Adam weight decay.
        batch_size: frames per gradient step.
        max_epochs: upper bound on passes over the training frames.
        patience: stop after this many epochs without a better validation loss.
        val_fraction: fraction of episodes held out for validation / early stopping.
        seed: seeds initialisation, shuffling and the split.
        device: torch device (the baselines are meant to run on ``cpu``).
        use_giver_state: also condition on the current giver/robot xyz (like ACT's
            ``observation.state``). Off by default: the receiver history alone, exactly what the
            planner sees, and the input that works in the env (where the "giver" is the robot's
            own TCP, so the model would learn to copy it and never move toward the person).
    """

    history: int = 10
    horizon: int = 30
    hidden: tuple[int, ...] = (256, 256, 256)
    dropout: float = 0.0
    lr: float = 1e-3
    weight_decay: float = 0.0
    batch_size: int = 256
    max_epochs: int = 50
    patience: int = 5
    val_fraction: float = 0.1
    seed: int = 0
    device: str = "cpu"
    use_giver_state: bool = False

    def __post_init__(self) -> None:
        self.hidden = tuple(int(h) for h in self.hidden)
        FeatureSpec(history=self.history, horizon=self.horizon)  # validates W and H
        if not self.hidden or min(self.hidden) < 1:
            raise ValueError(
                f"hidden must be a non-empty list of positive widths, got {self.hidden}"
            )
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        for name in ("lr", "batch_size", "max_epochs", "patience"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")
        if self.weight_decay < 0:
            raise ValueError(f"weight_decay must be >= 0, got {self.weight_decay}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")

    @property
    def spec(self) -> FeatureSpec:
        return FeatureSpec(history=self.history, horizon=self.horizon)

    @classmethod
    def from_dict(cls, d: dict, source: str = "config") -> BCMLPConfig:
        """From a checkpoint's JSON: every field present and of its type (see
        ``config_from_dict``)."""
        return config_from_dict(cls, d, source)


class BCMLPNet(nn.Module):
    """Standardise -> MLP -> un-standardise; the statistics are buffers (saved with the weights)."""

    def __init__(
        self,
        env_dim: int,
        horizon: int,
        hidden: tuple[int, ...],
        dropout: float = 0.0,
        use_state: bool = True,
    ):
        super().__init__()
        self.horizon = horizon
        self.use_state = use_state
        in_dim = env_dim + (3 if use_state else 0)
        n_in = in_dim
        layers: list[nn.Module] = []
        for width in hidden:
            layers += [nn.Linear(in_dim, width), nn.ReLU()]
            if dropout > 0:
                layers.append(nn.Dropout(dropout))
            in_dim = width
        layers.append(nn.Linear(in_dim, horizon * 3))
        self.mlp = nn.Sequential(*layers)
        self.register_buffer("in_mean", torch.zeros(n_in))
        self.register_buffer("in_std", torch.ones(n_in))
        self.register_buffer("out_mean", torch.zeros(3))
        self.register_buffer("out_std", torch.ones(3))

    def set_stats(self, frames: FrameArrays) -> None:
        """Set the normalisation statistics from training frames (valid chunk rows only)."""
        parts = [frames.env_state, frames.state] if self.use_state else [frames.env_state]
        x = np.concatenate(parts, axis=1).astype(np.float64)
        y = frames.action[~frames.action_is_pad].astype(np.float64)
        self.in_mean.copy_(torch.as_tensor(x.mean(0)))
        self.in_std.copy_(torch.as_tensor(np.maximum(x.std(0), MIN_STD)))
        self.out_mean.copy_(torch.as_tensor(y.mean(0)))
        self.out_std.copy_(torch.as_tensor(np.maximum(y.std(0), MIN_STD)))

    def forward_normalized(self, env_state: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        """(B, H, 3) standardised chunk."""
        x = torch.cat([env_state, state], dim=-1) if self.use_state else env_state
        x = (x - self.in_mean) / self.in_std
        return self.mlp(x).view(-1, self.horizon, 3)

    def forward(self, env_state: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        """(B, H, 3) giver xyz chunk in metres."""
        return self.forward_normalized(env_state, state) * self.out_std + self.out_mean

    def loss(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """Masked MSE of the standardised chunk."""
        pred = self.forward_normalized(batch["env_state"], batch["state"])
        target = (batch["action"] - self.out_mean) / self.out_std
        valid = (~batch["action_is_pad"]).unsqueeze(-1).to(pred.dtype)
        return ((pred - target) ** 2 * valid).sum() / (valid.sum() * 3).clamp_min(1.0)


def _tensors(frames: FrameArrays, device: str) -> dict[str, torch.Tensor]:
    return {
        "env_state": torch.as_tensor(frames.env_state, device=device),
        "state": torch.as_tensor(frames.state, device=device),
        "action": torch.as_tensor(frames.action, device=device),
        "action_is_pad": torch.as_tensor(frames.action_is_pad, device=device),
    }


@torch.no_grad()
def _eval_loss(net: BCMLPNet, data: dict[str, torch.Tensor], batch_size: int = 4096) -> float:
    net.eval()
    n = data["env_state"].shape[0]
    total, weight = 0.0, 0.0
    for i in range(0, n, batch_size):
        b = {k: v[i : i + batch_size] for k, v in data.items()}
        w = float((~b["action_is_pad"]).sum())
        total += float(net.loss(b)) * w
        weight += w
    return total / max(weight, 1.0)


class BCMLPAgent(GiverConditionedAgent):
    """The BC-MLP baseline behind the common agent interface.

    ``predict`` and ``predict_sequence`` need the current giver position (see
    :mod:`handover_env.data.features`); ``predict_episode`` (the open-loop protocol) takes it from
    the
    episode at the query frame, ``act`` from the robot's ``ee_pos``.

    Args:
        config: model and training settings.
        params: Theta (t_f is used by ``act``); closed_loop, layout: see ``PredictiveAgent``.
    """

    def __init__(
        self,
        config: BCMLPConfig | None = None,
        params: HandoverParams | None = None,
        closed_loop: ClosedLoopConfig | None = None,
        layout: ObsLayout | None = None,
    ):
        self.config = config or BCMLPConfig()
        GiverConditionedAgent.__init__(self, params, closed_loop, layout)
        self.horizon = self.config.horizon
        torch.manual_seed(self.config.seed)
        self.net = BCMLPNet(
            self.config.spec.env_dim, self.config.horizon, self.config.hidden, self.config.dropout,
            self.config.use_giver_state,
        )
        self.net.eval()
        self.fitted = False
        self.train_log: dict = {}
        self._giver_now: np.ndarray | None = None

    # ------------------------------------------------------------------ training
    def fit(
        self,
        dataset: HandoverDataset,
        out_dir: str | os.PathLike | None = None,
        resume: bool = False,
        progress: bool = False,
        max_epochs: int | None = None,
        log: Callable[[str], None] | None = None,
    ) -> BCMLPAgent:
        """Train on ``dataset`` with early stopping; optionally checkpoint every epoch to
        ``out_dir``.

        Args:
            dataset: demonstrations; a validation split of whole episodes is held out.
            out_dir: checkpoint folder, rewritten after every epoch (best weights + training state).
            resume: continue from the training state in ``out_dir``.
            progress: show a tqdm bar per epoch with the loss.
            max_epochs: overrides ``config.max_epochs``.
            log: called with one line per epoch.
        """
        cfg = self.config
        train_idx, val_idx = split_train_val(dataset, cfg.val_fraction, cfg.seed)
        train = dataset_frames(dataset.subset(train_idx), cfg.spec)
        val = dataset_frames(dataset.subset(val_idx), cfg.spec)
        max_epochs = cfg.max_epochs if max_epochs is None else int(max_epochs)

        torch.manual_seed(cfg.seed)
        self.net = BCMLPNet(
            cfg.spec.env_dim, cfg.horizon, cfg.hidden, cfg.dropout, cfg.use_giver_state
        )
        self.net.to(cfg.device)
        self.net.set_stats(train)
        opt = torch.optim.Adam(self.net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        split = {
            "train": [dataset[i].source_id for i in train_idx],
            "val": [dataset[i].source_id for i in val_idx],
        }
        tr = _tensors(train, cfg.device)
        va = _tensors(val, cfg.device)
        n = len(train)
        batches_per_epoch = max(1, math.ceil(n / cfg.batch_size))

        def one_epoch(epoch: int) -> float:
            """One pass over the training frames, shuffled by (seed, epoch): resumable."""
            self.net.train()
            gen = torch.Generator().manual_seed(cfg.seed * 100_003 + epoch)
            perm = torch.randperm(n, generator=gen)
            running = 0.0
            for i in range(0, n, cfg.batch_size):
                idx = perm[i : i + cfg.batch_size]
                loss = self.net.loss({k: v[idx] for k, v in tr.items()})
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                running += loss.item()
            return running / batches_per_epoch

        state, best = trainer.run(
            self.net,
            opt,
            one_epoch,
            lambda: _eval_loss(self.net, va),
            counter="epoch",
            total=max_epochs,
            split=split,
            describe=lambda s: (
                f"epoch {s['epoch']:3d}  train {s['train_loss'][-1]:.5f}  "
                f"val {s['val_loss'][-1]:.5f}  best {s['best_val']:.5f} @ {s['best_epoch']}"
            ),
            write_model=self._write_model,
            checks=trainer.ResumeChecks(
                config=self._config_dict(),
                saved_config=lambda o: _read_config(o)["config"],
                resumable=RESUMABLE_CHANGES,
                check_state=_check_state,
                check_best=lambda tensors, source: _check_stats(tensors, source, cfg),
            ),
            out_dir=out_dir,
            resume=resume,
            patience=cfg.patience,
            diverged="BC-MLP",
            desc="bc-mlp",
            progress=progress,
            log=log,
        )
        self.net.load_state_dict(best)
        self.net.eval()
        self.fitted = True
        self.train_log = state
        return self

    # ------------------------------------------------------------------ inference
    def _require_fitted(self) -> None:
        if not self.fitted:
            raise RuntimeError(
                "BCMLPAgent is not trained: call fit(dataset) or BCMLPAgent.load(dir)"
            )

    @torch.no_grad()
    def predict_batch(self, env_state: np.ndarray, state: np.ndarray) -> np.ndarray:
        """(B, H, 3) giver chunks for B feature rows (env_state (B, 2W), state (B, 3))."""
        self._require_fitted()
        env = torch.as_tensor(np.asarray(env_state, dtype=np.float32), device=self.config.device)
        st = torch.as_tensor(np.asarray(state, dtype=np.float32), device=self.config.device)
        if (
            env.ndim != 2
            or env.shape[1] != self.config.spec.env_dim
            or st.shape != (env.shape[0], 3)
        ):
            raise ValueError(
                f"expected env_state (B, {self.config.spec.env_dim}) and state (B, 3), "
                f"got {tuple(env.shape)} and {tuple(st.shape)}"
            )
        self.net.eval()
        return self.net(env, st).cpu().numpy().astype(np.float64)

    # ------------------------------------------------------------------ closed loop
    def stream_predict(self) -> np.ndarray:
        """The chunk for the newest camera frame, conditioned on the robot's current TCP."""
        return self.predict(np.asarray(self._history), self._giver_now)

    # ------------------------------------------------------------------ checkpoints
    def _config_dict(self) -> dict:
        """The config as JSON (what ``config.json`` holds under ``"config"``)."""
        return {**asdict(self.config), "hidden": list(self.config.hidden)}

    def _write_model(
        self, stage: Path, weights: dict[str, torch.Tensor], state: dict | None
    ) -> None:
        """``model.safetensors`` (``weights``) and ``config.json`` into the staging folder."""
        save_file(
            {k: v.contiguous().cpu() for k, v in weights.items()}, stage / "model.safetensors"
        )
        write_json(
            stage / "config.json",
            checkpoint_meta.checkpoint_json(CHECKPOINT_TYPE, CHECKPOINT_FORMAT, self.config, state),
        )

    def save(self, path: str | os.PathLike) -> Path:
        """Write ``config.json`` + ``model.safetensors`` (weights and normalisation) to ``path``, as
        a unit."""
        self._require_fitted()
        out = Path(path)
        with staged_write(out) as stage:
            self._write_model(stage, self.net.state_dict(), self.train_log)
        return out

    @classmethod
    def load(cls, path: str | os.PathLike, device: str = "cpu", **closed_loop_kwargs) -> BCMLPAgent:
        """Load a checkpoint written by :meth:`save` or by ``train.py bc-mlp``.

        Every file is validated first (see the module docstring); any problem raises
        :class:`~baselines.checkpoint_io.CheckpointError` naming the file. ``closed_loop_kwargs``
        (params, closed_loop, layout) go to the constructor.
        """
        path = check_loadable(path, ("config.json", "model.safetensors"), "BC-MLP")
        saved = _read_config(path)
        cfg = BCMLPConfig.from_dict(
            {**saved["config"], "device": device}, str(path / "config.json")
        )
        agent = cls(cfg, **closed_loop_kwargs)
        weights = path / "model.safetensors"
        tensors = load_tensors(weights, expected_of(agent.net.state_dict()))
        _check_stats(tensors, weights, cfg)
        agent.net.load_state_dict(tensors)
        agent.net.to(device).eval()
        agent.fitted = True
        agent.train_log = saved.get("training", {})
        return agent


def _check_stats(tensors: dict[str, torch.Tensor], source: Path, cfg: BCMLPConfig) -> None:
    """The normalisation statistics within what the data can produce (:mod:`baselines.norm_bounds`:
    means within the features' ±100 m / ±200 m, std in [``MIN_STD``, that bound]); a zero std
    would turn every prediction into NaN, a huge one into a huge number."""
    limits = feature_limits(cfg.spec.env_dim)
    giver = limits[ACTION]
    inputs = limits[OBS_ENV_STATE]
    if cfg.use_giver_state:  # the giver xyz follows the receiver history
        inputs = np.concatenate([inputs, giver])
    for key, limit in (("in_mean", inputs), ("in_std", inputs), ("out_mean", giver),
                       ("out_std", giver)):
        check_stat(source, key, tensors[key], key.rpartition("_")[2], limit, MIN_STD)


def _check_state(state: object, source: Path) -> dict:
    """A ``state.json`` whose fields have their types and agree with each other, or
    CheckpointError."""
    return trainer.check_state(state, source, "epoch", {"bad_epochs": int, "stopped_early": bool})


def _read_config(path: Path) -> dict:
    """``config.json`` of a BC-MLP checkpoint folder, validated."""
    return checkpoint_meta.read_checkpoint_json(
        path, "config.json", CHECKPOINT_TYPE, CHECKPOINT_FORMAT, BCMLPConfig, "BC-MLP"
    )


__all__ = ["BCMLPAgent", "BCMLPConfig", "BCMLPNet"]
