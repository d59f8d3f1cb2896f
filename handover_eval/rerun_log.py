"""``evaluate.py closed-loop --rerun PATH``: one closed-loop episode as a Rerun recording (.rrd),
to scrub through in the Rerun viewer (``rerun PATH``).

The episode is the run's first agent meeting its first receiver, run again in this process with
the same job as the run's (:func:`handover_eval.closedloop.run.plan_jobs`: the same Θ, sensing
profile, fold model and reset seed), so its outcome is the run's row for that pair. At every env
step (30 Hz, timeline ``sim_time``, the env's own clock) it logs:

* ``world/person/joints`` and ``world/person/bones``: the simulated person's skeleton, its 13
  segment origins (:data:`handover_env.person.skeleton.SEGMENTS`, read from MuJoCo's bodies)
  and the bones from each segment to its parent, plus the right hand's grip point;
  ``world/person/body``: the body's collision capsules (as thick line segments of their radius)
  and the skull sphere, where they are after the contacts;
* ``world/robot/tcp``: the robot's tool centre point (the 2F-85's pinch site);
* ``world/bottle``: the handed-over object's centre;
* ``wrist/force`` (the wrist F/T model's force magnitude, N, what the release compares with
  f_r) and ``wrist/release_threshold`` (f_r);
* ``events``: the person's state changes, the reach onset, the grasp, the gripper's release and
  the outcome with the benchmark's first-failure name (:mod:`handover_eval.benchmark.outcomes`).

The recording is built in memory and written once through
:func:`handover_eval.reporting.atomic_write_bytes`. It needs the ``rerun-sdk`` package, which
LeRobot (the ``[baselines]`` extra) installs; it opens no network connection (no viewer is
spawned, nothing is served).
"""

from __future__ import annotations

import dataclasses
import math
import os
import uuid
from pathlib import Path
from typing import Any

import numpy as np

from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.benchmark.outcomes import events, first_failure
from handover_eval.closedloop.models import model_for
from handover_eval.closedloop.run import ClosedLoopEvalConfig, plan_jobs
from handover_eval.closedloop.worker import EpisodeJob
from handover_eval.episodes import make_env, run_receiver
from handover_eval.methods import MethodOptions
from handover_eval.receivers import FIT_ALL, ReceiverSpec
from handover_eval.reporting import atomic_write_bytes

APPLICATION = "handover_env"


def check_rerun_path(path: str) -> Path:
    """The ``--rerun`` file: a ``.rrd`` name whose folder exists (checked before the run)."""
    p = Path(os.path.expanduser(path))
    if p.suffix != ".rrd":
        raise ValueError(f"--rerun must name a .rrd file, got {path!r}")
    if not p.parent.is_dir():
        raise ValueError(f"--rerun {path!r}: the folder {str(p.parent)!r} does not exist")
    try:
        import rerun  # noqa: F401
    except ImportError:
        raise ValueError("--rerun needs the rerun-sdk package (LeRobot, in the [baselines] "
                         "extra, installs it)") from None
    return p


def first_job(config: ClosedLoopEvalConfig, receivers: list[ReceiverSpec],
              dataset: HandoverDataset, options: MethodOptions, cache_dir: Path,
              fit_all: bool) -> EpisodeJob:
    """The job of the run's first agent and the first receiver it meets (one receiver), planned
    as the run plans it. ``fit_all``: the run had ``--replay-data`` (models of all of --data)."""
    agent = config.agents[0]
    specs = [s for s in receivers if not roster.entry(agent).replays_only or s.set == "replay"]
    if not specs:
        raise ValueError(f"--rerun: {agent} meets none of the receivers")
    if fit_all:
        n = len(dataset)
        splits: dict[int, tuple[np.ndarray, np.ndarray]] = {
            FIT_ALL: (np.arange(n, dtype=np.int64), np.arange(0, dtype=np.int64))}
    else:
        splits = dict(enumerate(dataset.stratified_kfold(config.folds, config.seed)))
    token = f"rerun-{os.getpid()}-{uuid.uuid4().hex}"
    jobs = plan_jobs(dataclasses.replace(config, agents=(agent,)), specs[:1], splits, options,
                     cache_dir, token)
    return jobs[0]


def _num(v: Any) -> float:
    return math.nan if v is None else float(v)


class EpisodeLogger:
    """The ``on_step`` callback of :func:`handover_env.rollout.run_episode` that logs one env
    step into a Rerun recording (module docstring)."""

    def __init__(self, rec: Any, env: Any, release_force: float) -> None:
        import mujoco
        import rerun as rr

        from handover_env.person.body_model import body_ids
        from handover_env.person.skeleton import SEGMENTS

        self.rr, self.rec, self.env = rr, rec, env.unwrapped
        ids = body_ids(self.env.model)
        self.bodies, self.grip = ids.bodies, ids.grip_site
        self.hand = next(i for i, s in enumerate(SEGMENTS) if s.name.endswith("hand_r"))
        self.bones = [(i, s.parent) for i, s in enumerate(SEGMENTS) if s.parent >= 0]
        self.tcp = self.env.ids.tcp_site
        m = self.env.model
        self.capsules = ids.geoms[m.geom_type[ids.geoms] == mujoco.mjtGeom.mjGEOM_CAPSULE]
        self.spheres = ids.geoms[m.geom_type[ids.geoms] == mujoco.mjtGeom.mjGEOM_SPHERE]
        self.release_force = release_force
        self.state: str | None = None
        self.seen: set[str] = set()
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def event(self, text: str, level: str = "INFO") -> None:
        self.rec.log("events", self.rr.TextLog(text, level=level))

    def __call__(self, step: int, info: dict) -> None:
        rr, rec, d = self.rr, self.rec, self.env.data
        rec.set_time("sim_time", duration=float(info["time"]))
        joints = d.xpos[self.bodies]
        grip = d.site_xpos[self.grip]
        rec.log("world/person/joints", rr.Points3D(np.vstack([joints, grip]), radii=0.025,
                                                   colors=[80, 140, 220]))
        strips = [np.stack([joints[i], joints[p]]) for i, p in self.bones]
        strips.append(np.stack([joints[self.hand], grip]))
        rec.log("world/person/bones", rr.LineStrips3D(strips, colors=[80, 140, 220]))
        m, caps = self.env.model, self.capsules
        axis = d.geom_xmat[caps].reshape(-1, 3, 3)[:, :, 2] * m.geom_size[caps, 1:2]
        centre = d.geom_xpos[caps]
        rec.log("world/person/body", rr.LineStrips3D(
            np.stack([centre - axis, centre + axis], axis=1), radii=m.geom_size[caps, 0],
            colors=[170, 190, 220]))
        rec.log("world/person/head", rr.Points3D(d.geom_xpos[self.spheres],
                                                 radii=m.geom_size[self.spheres, 0],
                                                 colors=[170, 190, 220]))
        rec.log("world/robot/tcp", rr.Points3D(d.site_xpos[self.tcp][None], radii=0.03,
                                               colors=[230, 120, 30]))
        rec.log("world/bottle", rr.Points3D(self.env.object_position()[None], radii=0.033,
                                            colors=[40, 170, 80]))
        rec.log("wrist/force", rr.Scalars(float(self.env.wrist_force_magnitude())))
        rec.log("wrist/release_threshold", rr.Scalars(self.release_force))
        state = info.get("receiver_state")
        if state != self.state:
            self.event(f"person: {self.state or 'start'} -> {state}")
            self.state = state
        for key, text in (("reach_onset_time", "reach onset"),
                          ("transfer_time", "grasp: the person's hand holds the bottle"),
                          ("release_time", "gripper released")):
            if info.get(key) is not None and key not in self.seen:
                self.seen.add(key)
                force = info.get("release_force")
                self.event(text + (f" (wrist force {force:.1f} N)" if key == "release_time"
                                   and force is not None else ""))


def log_job(dataset: HandoverDataset, job: EpisodeJob, path: Path) -> dict:
    """Run ``job``'s first receiver with the logger, write the .rrd to ``path``; returns the
    episode's row (:func:`handover_eval.episodes.episode_row`) with its ``first_failure``.

    The episode is :func:`handover_eval.episodes.run_receiver`'s, in a fresh env of the job's
    (not this process's cached one: the logger holds it, and it is closed after the episode)."""
    import rerun as rr

    model, _ = model_for(job.agent, dataset, job.model_fold, job.train_idx, job.options,
                         job.cache_dir, job.token)
    agent = roster.make_agent(job.agent, job.params, job.options, model)
    spec = job.receivers[0]
    p = job.params
    env = make_env(job.env, p, job.env_kwargs)
    title = f"{job.agent} meets {spec.set} {spec.key} (seed {spec.seed})"
    rec = rr.RecordingStream(APPLICATION, recording_id=title)
    stream = rec.binary_stream()
    try:
        rec.log("description", rr.TextDocument(title), static=True)
        logger = EpisodeLogger(rec, env, p.release_force)
        row = run_receiver(job, agent, spec, dataset, roster.entry(job.agent), on_step=logger,
                           env=env)
        row["wall_s"] = math.nan
        row["first_failure"] = first_failure(row["outcome"], events(row))
        outcome = row["outcome"] + (f" (first failed check: {row['first_failure']})"
                                    if row["first_failure"] else "")
        handover = _num(row.get("handover_time"))
        logger.event(f"outcome: {outcome}" + (f", handover time {handover:.2f} s"
                                               if math.isfinite(handover) else ""),
                     "INFO" if row["outcome"] == "success" else "WARN")
        data = stream.read(flush=True)
    finally:
        env.close()
    atomic_write_bytes(path, data)
    return row
