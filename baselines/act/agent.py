"""The ACT agent: LeRobot 0.4.x's own ``ACTPolicy`` behind the common agent interface.

State-only ACT: no camera, no vision backbone, no pretrained weights, no network.

| ACT input / output | feature type | shape | content (:mod:`handover_env.data.features`) |
|---|---|---|---|
| ``observation.environment_state`` | ENV | (2 W,) | receiver base xy history (xy + offsets) |
| ``observation.state`` | STATE | (3,) | current giver xyz (robot TCP in the env) |
| ``action`` | ACTION | (3,) | giver xyz; the policy predicts a chunk of H=30 |

Training goes through LeRobot's machinery (:mod:`baselines.act.data`): the dataset is exported with
:func:`handover_env.data.lerobot_export.export_lerobot`, read back as a ``LeRobotDataset`` with
``delta_timestamps`` for the action chunk, normalised by ``make_act_pre_post_processors`` with
statistics (``get_feature_stats``) of the training episodes for all three features (ENV, STATE and
ACTION all MEAN_STD), and optimised with ``ACTPolicy.forward`` (L1 + KL loss) under AdamW
(``fused`` on CPU) with the gradient clipping of LeRobot's ACT preset; the loop around the step is
the shared :func:`baselines.trainer.run`. The samples are normalised once, not per batch (bitwise
the same tensors), and on CPU the dropout masks come from :mod:`baselines.act.dropout`.
``fit_lerobot(..., episodes=...)`` trains on a subset of an export's episodes (split and
statistics from that subset only), so k-fold evaluations export the whole dataset once
(:mod:`handover_eval.act_folds`).

In an env the agent is a :class:`agents.predictive.PredictiveAgent` like the planner (same ready
pose, yaw rule and t_f of Theta), except for the ensembling: each new camera frame goes through
``ACTPolicy.select_action``, i.e. LeRobot's ``ACTTemporalEnsembler``
(``temporal_ensemble_coeff=0.01``, ``n_action_steps=1``), as the paper does. The returned current
action plus the ensembler's remaining future rows form the ensembled chunk from which the
target at t_f is read (:class:`EnsembledChunk`).

Checkpoint folder (format 2, :mod:`baselines.act.config`): ``config.json`` + ``model.safetensors``
(``ACTPolicy.save_pretrained``), ``policy_preprocessor*.json/.safetensors`` and
``policy_postprocessor*`` (the normalisation statistics), ``handover_act.json`` (our config,
features and training summary) and ``training_state/`` (last weights, optimizer, RNG and step) for
``--resume``. Each checkpoint is written as one unit (:func:`baselines.checkpoint_io.staged_write`).
Loading writes nothing (an interrupted commit is refused, never finished; ``--resume`` finishes
it) and validates every file first (:mod:`baselines.act.files`: LeRobot's processor JSON can name
any importable class, so it is checked against an allow-list and never handed to LeRobot) and
builds the policy and processors from our own validated config.

Reproducibility: training runs under :func:`reproducible` (seeded Python, numpy and torch RNGs,
one torch thread, ``torch.use_deterministic_algorithms``), with data order and dropout masks drawn
from the seed and the step, so a seed gives bit-identical weights in any process
(``tests/baselines/test_act_determinism.py``), whatever torch thread count the caller set.
"""

from __future__ import annotations

import contextlib
import math
import os
import random
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path

import numpy as np

from handover_env.extras import missing_extra

try:
    import lerobot  # noqa: F401 - ACT is LeRobot's ACTPolicy
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None

from agents.predictive import ClosedLoopConfig
from baselines import checkpoint_meta, trainer
from baselines.act.config import ACTAgentConfig
from baselines.act.data import normalise_samples, prepared_export, training_samples
from baselines.act.dropout import DropoutMasks, fast_dropout
from baselines.act.files import POSTPROCESSOR_JSON, PREPROCESSOR_JSON, validated_stats
from baselines.checkpoint_io import (
    CheckpointError,
    check_loadable,
    expected_of,
    load_tensors,
    staged_write,
    write_json,
)
from baselines.giver_conditioned import GiverConditionedAgent
from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_env.data.features import (
    ACTION,
    ACTION_DIM,
    OBS_ENV_STATE,
    OBS_STATE,
    encode_history,
    validate_giver,
)
from handover_env.envs.observation import ObsLayout

CHECKPOINT_TYPE = "act"
CHECKPOINT_FORMAT = 2
HANDOVER_JSON = "handover_act.json"
#: torch intra-op threads while ACT trains. Summation order, hence the last bits of every step,
#: depends on the thread count; one thread makes a seed reproducible in any process (parallelism
#: comes from processes).
TRAIN_THREADS = 1
#: Config fields a resumed run may change (a longer run, another validation cadence or device).
RESUMABLE_CHANGES = frozenset({"steps", "eval_every", "device"})


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

    # Rows per network call in open-loop evaluation: bounds the activations and keeps the
    # decoder's activations in cache.
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
        with prepared_export(dataset, export_root, self.config.spec, rebuild_export, progress,
                             log) as root:
            return self.fit_lerobot(root, out_dir=out_dir, resume=resume, progress=progress,
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
        train, val, stats, split = training_samples(root, repo_id, cfg.spec, cfg.val_fraction,
                                                    cfg.seed, episodes)
        with reproducible(cfg.seed):
            return self._train(train, val, stats, split, total_steps, out_dir, resume, progress,
                               log)

    def _train(
        self,
        train: dict[str, torch.Tensor],
        val: dict[str, torch.Tensor],
        stats: dict,
        split: dict[str, list[str]],
        total_steps: int,
        out_dir: str | os.PathLike | None,
        resume: bool,
        progress: bool,
        log: Callable[[str], None] | None,
    ) -> ACTAgent:
        """:meth:`fit_lerobot`'s training (under :func:`reproducible`): the policy, its processors
        and optimiser, and the step and validation functions :func:`baselines.trainer.run`
        drives."""
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
        n = train[ACTION].shape[0]
        per_epoch = max(1, n // cfg.batch_size)
        perm: torch.Tensor | None = None
        masks = DropoutMasks(cfg.seed)
        use_fast = cfg.fast_dropout and torch.device(cfg.device).type == "cpu"

        def one_step(step: int) -> float:
            """One AdamW step on batch ``step`` of the permutation of (seed, epoch): resumable."""
            nonlocal perm
            epoch, pos = divmod(step, per_epoch)
            if perm is None or pos == 0:
                gen = torch.Generator().manual_seed(cfg.seed * 100_003 + epoch)
                perm = torch.randperm(n, generator=gen)
            idx = perm[pos * cfg.batch_size : (pos + 1) * cfg.batch_size]
            self.policy.train()
            masks.reseed(step)
            loss, _ = self.policy.forward({k: v[idx] for k, v in train.items()})
            if not torch.isfinite(loss):
                raise FloatingPointError(
                    f"ACT training diverged at step {step + 1} (loss {float(loss)}); check the "
                    "data's coordinates and the learning rate"
                )
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.policy.parameters(), preset.grad_clip_norm)
            opt.step()
            return loss.item()

        with fast_dropout(self.policy, masks) if use_fast else contextlib.nullcontext():
            state, best = trainer.run(
                self.policy,
                opt,
                one_step,
                lambda: self._val_l1(val),
                counter="step",
                total=total_steps,
                split=split,
                describe=lambda s: (
                    f"step {s['step']:6d}  train {s['train_loss'][-1]:.4f}  "
                    f"val L1 {s['val_loss'][-1]:.4f}  best {s['best_val']:.4f} @ {s['best_step']}"
                ),
                write_model=self._write_model,
                checks=trainer.ResumeChecks(
                    config=asdict(cfg),
                    saved_config=lambda o: _read_handover_json(o)["config"],
                    resumable=RESUMABLE_CHANGES,
                    check_state=_check_state,
                ),
                out_dir=out_dir,
                resume=resume,
                every=cfg.eval_every,
                rng=True,
                desc="act",
                progress=progress,
                log=log,
                loss_every=25,
            )
        self.policy.load_state_dict(best)
        self.policy.eval()
        self.fitted = True
        self.train_log = state
        return self

    @torch.no_grad()
    def _val_l1(self, val: dict[str, torch.Tensor], batch_size: int = 256) -> float:
        """Masked L1 of the normalised chunk (the reconstruction term of ACT's loss), zero latent.

        ``val`` is already normalised (:func:`~baselines.act.data.normalise_samples`);
        ``batch_size`` rows per network call bound the activations.
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
            checkpoint_meta.checkpoint_json(CHECKPOINT_TYPE, CHECKPOINT_FORMAT, self.config, state),
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

        Every file is validated before it is used (:mod:`baselines.act.files`); LeRobot never
        parses the checkpoint's JSON: the policy and the processors are built from our validated
        config and only their tensors are loaded. Any problem raises
        :class:`~baselines.checkpoint_io.CheckpointError` naming the file (and the processor step).
        ``closed_loop_kwargs`` (params, closed_loop, layout) go to ``PredictiveAgent``.
        """
        from lerobot.policies.act.modeling_act import ACTPolicy
        from lerobot.policies.act.processor_act import make_act_pre_post_processors

        path = check_loadable(path, (HANDOVER_JSON, "config.json", "model.safetensors",
                                     PREPROCESSOR_JSON, POSTPROCESSOR_JSON),
                              "ACT")  # writes nothing: an interrupted commit is refused
        saved = _read_handover_json(path)
        trained = ACTAgentConfig.from_dict(saved["config"], str(path / HANDOVER_JSON))
        cfg = ACTAgentConfig.from_dict(
            {**saved["config"], "device": device}, str(path / HANDOVER_JSON)
        )
        pre_stats, post_stats = validated_stats(path, trained)
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
    return checkpoint_meta.read_checkpoint_json(
        path, HANDOVER_JSON, CHECKPOINT_TYPE, CHECKPOINT_FORMAT, ACTAgentConfig, "ACT",
        upgrades={1: ACTAgentConfig.from_legacy},
    )
