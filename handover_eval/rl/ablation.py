"""Issue 36's ablation table: each RL run's learning curve beside its closed-loop evaluation.

One row is one training seed: a ``train.py rl`` checkpoint folder (read through the safe loader,
:func:`baselines.rl.files.read_record`, and its training state checked as ``--resume`` checks
it) and the ``--out`` folder of an ``evaluate.py closed-loop --rl-checkpoint`` run of it (its
``closed_loop_episodes.csv`` and ``closed_loop_paired.csv``, read as regular UTF-8 files inside
that folder). Rows sharing a label are the seeds of one configuration.

Per row: the learning curve's first and last success rate and handover time on the fixed training
receivers; env steps, wall time and steps/s; and, from the closed loop, on the scripted walkers
(ID, OOD) and the replays: success, the median handover time over the successes, the share of
episodes whose body contact (any segment but the receiving hand, filtered) exceeds
:data:`CONTACT_N`, the median robot TCP jerk (RMS at 30 Hz), the premature releases and how many
of them came before the person began to reach (no reach onset by the release: the wrist force
that opened the gripper was the robot's own motion's), and the RL
agent minus the run's reference agent paired on the same receivers (the closed-loop command's
bootstrap CIs). The reference agents (``cv``, ``reactive``) are rows of their own, from the first
evaluation folder that ran them. Per configuration: the mean and the IQM over seeds of the paired
differences on the replays, with a 95 % stratified bootstrap interval over seeds
(:mod:`handover_eval.rl.statistics`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: N: the body-contact force the issues count (docs/results.md: contacts over 50 N).
CONTACT_N = 50.0
#: The closed-loop sets of a row: scripted walkers (the episodes' raw set) and all replays.
SETS: dict[str, str] = {"walker-id": "id", "walker-ood": "ood", "replay-all": "replay"}
#: The paired CSV's columns this reads.
PAIRED_COLUMNS = ("agent", "set", "metric", "diff", "diff_low", "diff_high", "ci_excludes_zero")
#: The agents an RL checkpoint is scored as.
RL_AGENTS = ("rl-residual", "rl-scratch")
MAX_PAIRED_BYTES = 5_000_000


class AblationError(ValueError):
    """A run or evaluation folder that cannot be read (one line naming the file)."""


@dataclass(frozen=True)
class AblationRun:
    """One row's inputs: the configuration's label, the checkpoint folder, the evaluation
    folder."""

    label: str
    run: Path
    evaluation: Path


@dataclass
class AgentScores:
    """One agent's closed-loop scores per set of :data:`SETS`: ``{set: {metric: value}}``."""

    agent: str
    sets: dict[str, dict[str, float]]


@dataclass
class AblationRow:
    """One seed: its curve, timing, closed-loop scores and paired differences."""

    label: str
    seed: int
    flags: str
    curve_start: dict[str, float]
    curve_end: dict[str, float]
    steps: int
    wall_s: float
    scores: AgentScores
    reference: str
    paired: dict[str, dict[str, tuple[float, float, float, bool]]] = field(default_factory=dict)

    @property
    def steps_per_s(self) -> float:
        return self.steps / self.wall_s if self.wall_s > 0 else math.nan


def _float(row: Mapping[str, str], key: str, path: Path) -> float:
    try:
        return float(row[key])
    except (TypeError, ValueError):
        raise AblationError(f"{path}: {key} {row[key]!r} is not a number") from None


def agent_scores(rows: Sequence[Mapping[str, str]], agent: str, path: Path) -> AgentScores:
    """``agent``'s success, median handover time, share over :data:`CONTACT_N`, median robot
    jerk and premature releases per set of :data:`SETS`, from closed-loop episode rows."""
    out: dict[str, dict[str, float]] = {}
    for name, raw in SETS.items():
        mine = [r for r in rows if r["agent"] == agent and r["set"] == raw]
        if not mine:
            raise AblationError(f"{path}: no {raw} episodes of {agent}")
        ok = [r["is_success"] == "True" for r in mine]
        times = [_float(r, "handover_time", path) for r, s in zip(mine, ok, strict=True) if s]
        contact = [_float(r, "body_contact_force", path) for r in mine]
        jerk = [_float(r, "robot_jerk_rms", path) for r in mine]
        premature = [r for r in mine if r["outcome"] == "premature_release"]
        out[name] = {
            "n": float(len(mine)),
            "success": float(np.mean(ok)),
            "handover_time": float(np.median(times)) if times else math.nan,
            "contact_over": float(np.mean([c > CONTACT_N for c in contact])),
            "robot_jerk": float(np.median(jerk)),
            "premature": float(len(premature)),
            "premature_before_reach": float(sum(
                not _float(r, "reach_onset_time", path) <= _float(r, "release_time", path)
                for r in premature)),
        }
    return AgentScores(agent, out)


def paired_differences(rows: Sequence[Mapping[str, str]], agent: str, path: Path
                       ) -> dict[str, dict[str, tuple[float, float, float, bool]]]:
    """``{set: {metric: (diff, low, high, excludes 0)}}`` of ``agent`` against the reference,
    for success and handover time, from ``closed_loop_paired.csv``."""
    out: dict[str, dict[str, tuple[float, float, float, bool]]] = {}
    for r in rows:
        if r["agent"] == agent and r["set"] in SETS and r["metric"] in ("success",
                                                                        "handover_time"):
            out.setdefault(r["set"], {})[r["metric"]] = (
                _float(r, "diff", path), _float(r, "diff_low", path),
                _float(r, "diff_high", path), r["ci_excludes_zero"] == "True")
    for name in SETS:
        if set(out.get(name, {})) != {"success", "handover_time"}:
            raise AblationError(f"{path}: no paired success and handover time of {agent} on "
                                f"{name}")
    return out


def _curve_point(point: Mapping[str, float]) -> dict[str, float]:
    return {"success": float(point["success_rate"]), "handover_time": float(point["handover_time"])}


#: The config fields a row names when they differ from :class:`RLConfig`'s defaults: the
#: algorithm, the form and base, and issue 36's levers (docs/rl.md).
LEVER_FIELDS = ("algo", "form", "base", "use_sde", "sde_sample_freq", "action_noise",
                "noise_sigma", "action_tau", "last_actions", "privileged_critic", "warm_start",
                "action_change", "contact_penalty", "shaping", "sensing")


def _flags(config: object) -> str:
    """The fields of :data:`LEVER_FIELDS` of ``config`` that differ from :class:`RLConfig`'s
    defaults, as train.py flags."""
    from baselines.rl.config import RLConfig

    default = RLConfig()
    out = []
    for name in LEVER_FIELDS:
        v = getattr(config, name)
        if v != getattr(default, name):
            flag = "--" + name.replace("_", "-")
            out.append(flag if v is True else f"{flag} {v:g}" if isinstance(v, float)
                       else f"{flag} {v}")
    return " ".join(out) or "(the defaults)"


def read_row(spec: AblationRun) -> tuple[AblationRow, list]:
    """One :class:`AblationRow` from ``spec``'s folders, and the evaluation's episode rows."""
    from baselines.rl.files import read_record
    from baselines.rl.train import read_state
    from handover_eval.closedloop.presentation import read_episode_rows
    from handover_eval.reporting import read_folder_csv

    record, config = read_record(spec.run)
    state = read_state(spec.run, config, record)
    rows = read_episode_rows(spec.evaluation)
    path = spec.evaluation / "closed_loop_episodes.csv"
    agents = sorted({r["agent"] for r in rows} & set(RL_AGENTS))
    if len(agents) != 1:
        raise AblationError(f"{path}: expected one RL agent among {list(RL_AGENTS)}, got "
                            f"{agents}")
    paired_path = spec.evaluation / "closed_loop_paired.csv"
    paired_rows = read_folder_csv(spec.evaluation, "closed_loop_paired.csv", MAX_PAIRED_BYTES,
                                  PAIRED_COLUMNS, AblationError, inside="evaluation folder")
    references = sorted({r["agent"] for r in rows} - {agents[0]}
                        - {r["agent"] for r in paired_rows})
    row = AblationRow(
        label=spec.label, seed=config.seed, flags=_flags(config),
        curve_start=_curve_point(state["curve"][0]), curve_end=_curve_point(state["curve"][-1]),
        steps=int(state["steps"]), wall_s=float(state["wall_time_s"]),
        scores=agent_scores(rows, agents[0], path),
        reference=references[0] if len(references) == 1 else "",
        paired=paired_differences(paired_rows, agents[0], paired_path))
    return row, rows


def run_ablation(specs: Sequence[AblationRun], references: Sequence[str] = ("cv", "reactive")
                 ) -> tuple[list[AblationRow], list[AgentScores]]:
    """Every row of ``specs`` and the scores of each agent of ``references`` (from the first
    evaluation that ran it)."""
    if not specs:
        raise AblationError("no runs given")
    rows, refs = [], {}
    for spec in specs:
        for folder in (spec.run, spec.evaluation):
            if not Path(folder).is_dir():
                raise AblationError(f"{folder}: not a folder")
        row, episodes = read_row(spec)
        rows.append(row)
        for name in references:
            if name not in refs and any(r["agent"] == name for r in episodes):
                refs[name] = agent_scores(episodes, name,
                                          spec.evaluation / "closed_loop_episodes.csv")
    return rows, [refs[n] for n in references if n in refs]


def seed_summary(rows: Sequence[AblationRow]) -> list[dict[str, object]]:
    """Per configuration (label, in first-seen order): the seeds, and the mean and IQM over
    seeds of the paired success and handover-time differences on the replays, with their 95 %
    stratified bootstrap interval."""
    from handover_eval.rl.statistics import iqm, stratified_bootstrap_ci

    out = []
    for label in dict.fromkeys(r.label for r in rows):
        mine = [r for r in rows if r.label == label]
        entry: dict[str, object] = {"label": label, "seeds": [r.seed for r in mine],
                                    "reference": mine[0].reference}
        for metric in ("success", "handover_time"):
            x = np.array([r.paired["replay-all"][metric][0] for r in mine])
            point, low, high = stratified_bootstrap_ci(x[:, None], iqm)
            entry[f"{metric}_mean"] = float(x.mean())
            entry[f"{metric}_iqm"] = (point, low, high)
        out.append(entry)
    return out


def parse_run(text: str) -> AblationRun:
    """``LABEL=RUN_FOLDER:EVALUATION_FOLDER`` (the ``--run`` flag) as an :class:`AblationRun`."""
    label, sep, rest = text.partition("=")
    run, sep2, evaluation = rest.partition(":")
    if not (sep and sep2 and label.strip() and run and evaluation):
        raise AblationError(f"--run {text!r}: expected LABEL=RUN_FOLDER:EVALUATION_FOLDER")
    return AblationRun(label.strip(), Path(os.path.expanduser(run)),
                       Path(os.path.expanduser(evaluation)))


__all__ = ["AblationError", "AblationRow", "AblationRun", "AgentScores", "agent_scores",
           "paired_differences", "parse_run", "read_row", "run_ablation", "seed_summary"]
