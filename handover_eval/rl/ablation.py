"""Issue 36's ablation table: each RL run's learning curve beside its closed-loop evaluation.

One row is one training seed: a ``train.py rl`` checkpoint folder (read through the safe loader,
:func:`baselines.rl.files.read_record`, and its training state checked as ``--resume`` checks
it) and the ``--out`` folder of an ``evaluate.py closed-loop --rl-checkpoint`` run of it (its
``closed_loop_episodes.csv`` and ``closed_loop_paired.csv``, read as regular UTF-8 files inside
that folder). Rows sharing a label are the seeds of one configuration.

Seeds trained and evaluated at different times are tabled together through an earlier
``rl_ablation.csv`` of this command (:func:`read_table`, ``--table``). Its rows come back as they
were written: every float at full precision (a table written before 2026-12-08 holds six
significant digits), and a paired CI excludes 0 when it lies above or below it (the closed-loop
command's rule). A reference agent that a new evaluation also ran must have the same scores
there, or the evaluations did not meet the same receivers. The learning curves of a
configuration's seeds (every seed and the IQM band) are drawn from their
``seed-S/train_log.csv`` files (:func:`read_curves`, ``--curves``), the files ``train.py rl``
writes beside each checkpoint.

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
import re
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
#: The scores of an agent per set (:func:`agent_scores`), as the table's CSV names them.
METRICS = ("n", "success", "handover_time", "contact_over", "robot_jerk", "premature",
           "premature_before_reach")
#: A row's learning-curve metrics at its start and end (:func:`_curve_point`).
CURVE_METRICS = ("success", "handover_time")
#: The paired metrics of a row (:func:`paired_differences`).
PAIRED_METRICS = ("success", "handover_time")
MAX_PAIRED_BYTES = 5_000_000
#: Bytes of an earlier ``rl_ablation.csv`` or of one ``train_log.csv``.
MAX_TABLE_BYTES = 1_000_000
#: The columns of a ``train_log.csv`` the curves read.
CURVE_COLUMNS = ("steps", "success_rate", "handover_time", "return")
#: A configuration label that names a folder of the curves' output.
LABEL_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


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
        out[name] = {  # the keys of METRICS
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
        if r["agent"] == agent and r["set"] in SETS and r["metric"] in PAIRED_METRICS:
            out.setdefault(r["set"], {})[r["metric"]] = (
                _float(r, "diff", path), _float(r, "diff_low", path),
                _float(r, "diff_high", path), r["ci_excludes_zero"] == "True")
    for name in SETS:
        if set(out.get(name, {})) != set(PAIRED_METRICS):
            raise AblationError(f"{path}: no paired success and handover time of {agent} on "
                                f"{name}")
    return out


def _curve_point(point: Mapping[str, float]) -> dict[str, float]:
    """A learning-curve point as the row's :data:`CURVE_METRICS`."""
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


def run_ablation(specs: Sequence[AblationRun], references: Sequence[str] = ("cv", "reactive"),
                 tables: Sequence[Path] = ()) -> tuple[list[AblationRow], list[AgentScores]]:
    """The rows of every earlier table of ``tables`` (:func:`read_table`), then of every run of
    ``specs``, and the scores of each agent of ``references`` (from the first table or
    evaluation that has it; a later evaluation that ran it must agree, :func:`same_scores`).
    A configuration's seed given twice is refused."""
    if not specs and not tables:
        raise AblationError("no runs and no earlier table given")
    rows: list[AblationRow] = []
    refs: dict[str, tuple[AgentScores, Path]] = {}
    for table in tables:
        earlier, table_refs = read_table(Path(table))
        rows += earlier
        for ref in table_refs:
            if ref.agent in references:
                refs.setdefault(ref.agent, (ref, Path(table)))
    for spec in specs:
        for folder in (spec.run, spec.evaluation):
            if not Path(folder).is_dir():
                raise AblationError(f"{folder}: not a folder")
        row, episodes = read_row(spec)
        rows.append(row)
        path = spec.evaluation / "closed_loop_episodes.csv"
        for name in references:
            if any(r["agent"] == name for r in episodes):
                mine = agent_scores(episodes, name, path)
                if name not in refs:
                    refs[name] = (mine, path)
                elif not same_scores(mine, refs[name][0]):
                    raise AblationError(
                        f"{path}: the reference {name}'s scores differ from those of "
                        f"{refs[name][1]}: the evaluations did not meet the same receivers")
    seen: set[tuple[str, int]] = set()
    for r in rows:
        if (r.label, r.seed) in seen:
            raise AblationError(f"configuration {r.label!r} seed {r.seed} is given twice")
        seen.add((r.label, r.seed))
    return rows, [refs[n][0] for n in references if n in refs]


def same_scores(a: AgentScores, b: AgentScores) -> bool:
    """Whether two agents' scores agree on every set and metric to six significant digits (an
    older table's precision; NaN equal to NaN)."""
    def close(x: float, y: float) -> bool:
        return (math.isnan(x) and math.isnan(y)) or math.isclose(x, y, rel_tol=1e-5,
                                                                 abs_tol=1e-9)

    return a.sets.keys() == b.sets.keys() and all(
        all(close(a.sets[k][m], b.sets[k][m]) for m in METRICS) for k in a.sets)


def _table_columns() -> tuple[str, ...]:
    """The columns of an ``rl_ablation.csv`` that :func:`read_table` reads."""
    scores = [f"{name}_{m}" for name in SETS for m in METRICS]
    curve = [f"curve_{at}_{m}" for at in ("start", "end") for m in CURVE_METRICS]
    paired = [f"paired_{name}_{m}{end}" for name in SETS for m in PAIRED_METRICS
              for end in ("", "_low", "_high")]
    return ("configuration", "seed", "agent", *scores, *curve, "steps", "wall_s", "reference",
            *paired)


def read_table(path: Path) -> tuple[list[AblationRow], list[AgentScores]]:
    """The seed rows and the reference rows of an earlier ``rl_ablation.csv`` of this command
    (a regular UTF-8 file inside its folder, at most :data:`MAX_TABLE_BYTES`; every number
    checked; one :class:`AblationError` naming the file and the field)."""
    from handover_eval.closedloop.stats import ci_excludes_zero
    from handover_eval.reporting import read_folder_csv

    path = Path(path)
    lines = read_folder_csv(path.parent, path.name, MAX_TABLE_BYTES, _table_columns(),
                            AblationError, inside="table's folder",
                            missing_hint=" (not an rl_ablation.csv of evaluate.py rl-ablation)")

    def number(line: Mapping[str, str], key: str, finite: bool = True) -> float:
        v = _float(line, key, path)
        if finite and not math.isfinite(v):
            raise AblationError(f"{path}: {key} {line[key]!r} is not a finite number")
        return v

    def whole(line: Mapping[str, str], key: str) -> int:
        v = number(line, key)
        if v != int(v) or v < 0:
            raise AblationError(f"{path}: {key} {line[key]!r} is not a whole number >= 0")
        return int(v)

    def curve(line: Mapping[str, str], at: str) -> dict[str, float]:
        return {m: number(line, f"curve_{at}_{m}", finite=m == "success")
                for m in CURVE_METRICS}

    def scores(line: Mapping[str, str]) -> AgentScores:
        return AgentScores(line["agent"], {
            name: {m: number(line, f"{name}_{m}", finite=m != "handover_time") for m in METRICS}
            for name in SETS})

    rows, refs = [], []
    for line in lines:
        if line["seed"] == "":
            refs.append(scores(line))
            continue
        if line["agent"] not in RL_AGENTS:
            raise AblationError(f"{path}: agent {line['agent']!r} of a seed row is not one of "
                                f"{list(RL_AGENTS)}")
        paired: dict[str, dict[str, tuple[float, float, float, bool]]] = {}
        for name in SETS:
            for m in PAIRED_METRICS:
                d, lo, hi = (number(line, f"paired_{name}_{m}{end}")
                             for end in ("", "_low", "_high"))
                paired.setdefault(name, {})[m] = (d, lo, hi, ci_excludes_zero(lo, hi))
        rows.append(AblationRow(
            label=line["configuration"], seed=whole(line, "seed"), flags=line.get("flags", ""),
            curve_start=curve(line, "start"), curve_end=curve(line, "end"),
            steps=whole(line, "steps"), wall_s=number(line, "wall_s"), scores=scores(line),
            reference=line["reference"], paired=paired))
    return rows, refs


def read_curves(folder: Path) -> list[tuple[int, list[dict[str, float]]]]:
    """``(seed, curve)`` of every ``seed-S/train_log.csv`` in ``folder`` (a ``train.py rl
    --seeds`` output folder, or the same layout of committed logs), in seed order; each
    ``train_log.csv`` a regular UTF-8 file inside its folder, its success rate and return
    finite."""
    from handover_eval.reporting import read_folder_csv

    folder = Path(folder)
    if not folder.is_dir():
        raise AblationError(f"{folder}: not a folder")
    seeds = sorted((int(p.name[5:]), p) for p in folder.iterdir()
                   if re.fullmatch(r"seed-[0-9]{1,9}", p.name) and p.is_dir())
    if not seeds:
        raise AblationError(f"{folder}: no seed-S folders")
    out = []
    for seed, sub in seeds:
        lines = read_folder_csv(sub, "train_log.csv", MAX_TABLE_BYTES, CURVE_COLUMNS,
                                AblationError, inside="seed folder")
        path = sub / "train_log.csv"
        curve = []
        for line in lines:
            point = {k: _float(line, k, path) for k in CURVE_COLUMNS}
            if not all(math.isfinite(point[k]) for k in ("steps", "success_rate", "return")):
                raise AblationError(f"{path}: steps, success_rate and return must be finite")
            curve.append(point)
        out.append((seed, curve))
    return out


def parse_curves(text: str) -> tuple[str, Path]:
    """``LABEL=FOLDER`` (the ``--curves`` flag): the label names the output's folder, so it is
    letters, digits, ``_``, ``.`` and ``-`` only (:data:`LABEL_PATTERN`)."""
    label, sep, folder = text.partition("=")
    if not (sep and folder) or not LABEL_PATTERN.fullmatch(label) or label in (".", ".."):
        raise AblationError(f"--curves {text!r}: expected LABEL=FOLDER, LABEL of letters, "
                            "digits, _ . -")
    return label, Path(os.path.expanduser(folder))


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
           "paired_differences", "parse_curves", "parse_run", "read_curves", "read_row",
           "read_table", "run_ablation", "same_scores", "seed_summary"]
