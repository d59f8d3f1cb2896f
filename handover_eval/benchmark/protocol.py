"""Protocol v2 of the benchmark, as constants (docs/benchmark.md says what each one means).

A result is comparable with another only under the same :data:`PROTOCOL_VERSION` and the same
fingerprint of each track it reports (:func:`fingerprints`): the data the agent fit on, the data
it was scored on, and the receivers it met. Any change to a constant here that moves a number is
a new protocol version.

Open-loop track: Table I's stratified k-fold split (k = 10, seed 0; ID and OOD apart), queries at
every frame from frame 5, a 30-frame (1 s) horizon, and the metrics of
:mod:`handover_eval.openloop.protocol` (current-frame per-axis RMS, 3D RMS over 1 s, ADE/FDE at
0.5 s and 1 s). With ``--replay-data`` the agent fits on all of ``--data`` and is scored on every
episode of the other data instead.

Closed-loop track: ``DynamicHandover-v0`` on the ``"paper"`` sensing profile (:data:`SENSING`, the
env's default, passed explicitly so that a later default cannot move the protocol), the person
of :data:`PERSON` (passed explicitly too), at Θ̂, and the
receivers of :func:`receivers`: scripted ID and OOD walkers and the far-pass stress set on **test
seeds** (:data:`TEST_SEEDS`, never used by any tuning, training or development command of this
project, all of whose seeds are below :data:`TRAIN_SEED_LIMIT`), and recorded replays (held-out
folds 5-9 of ``--data``'s split, or every episode of ``--replay-data``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import numpy as np

from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval.openloop.protocol import OpenLoopProtocol
from handover_eval.receivers import ReceiverSpec

PROTOCOL_VERSION = 3
#: Every version this code can read (leaderboard, rescore); only this one is written. v1 (up to
#: handover_env 0.9): the person without the arm's yield and the draw-out by the gripper's open
#: side; v2: with them, but the top grasp, the passive joint damping and no reach offset of
#: their own; v3: the person of :data:`PERSON` (docs/benchmark.md, "Versions").
KNOWN_VERSIONS: tuple[int, ...] = (1, 2, 3)
TRACKS: tuple[str, ...] = ("openloop", "closedloop")

# ------------------------------------------------------------------------------ open-loop track
OPENLOOP_FOLDS = 10
OPENLOOP_SEED = 0
OPENLOOP = OpenLoopProtocol(horizon=30, first_query=5, stride=1)
#: The open-loop metrics: column -> label (all in mm; lower is better).
OPENLOOP_METRICS: dict[str, str] = {
    "rms_now_axis_mm": "current-frame RMS per axis",
    "rms_3d_mm": "3D RMS over 1 s",
    "ade_05_mm": "ADE 0.5 s",
    "fde_05_mm": "FDE 0.5 s",
    "ade_10_mm": "ADE 1 s",
    "fde_10_mm": "FDE 1 s",
}
OPENLOOP_SETS: tuple[str, ...] = ("id", "ood")

# ---------------------------------------------------------------------------- closed-loop track
THETA = HandoverParams()  # Θ̂ = (114.3, 17.1, 0.14, 7.1)
ENV_ID = "handover_env/DynamicHandover-v0"
#: The env's sensing profile (docs/sensing.md): the paper's robot, the env's default.
SENSING = "paper"
#: The person's switches (docs/simulator.md; the env's defaults at v3): their own reach offset,
#: the arm that yields to the robot, the held object drawn out by the gripper's open side, the
#: hand on the object's lower part, the elbow held as the recorded receivers held it, no passive
#: joint damping. v2's person: ``{"reach_offset": False, "arm_yield": True, "avoid_gripper":
#: True, "grasp_below": False, "recorded_elbow": False, "joint_damping": True}``.
PERSON = {"reach_offset": True, "arm_yield": True, "avoid_gripper": True, "grasp_below": True,
          "recorded_elbow": True, "joint_damping": False}
#: Every seed this project's own commands use (closed-loop 0.., 10000..; the simulated
#: participants' walks pid * 1000 + stream * 100 + k) lies below this: the tuning/training range.
TRAIN_SEED_LIMIT = 100_000_000
#: The first test seed of each scripted set.
TEST_SEEDS: dict[str, int] = {
    "walker-id": 200_000_000,
    "walker-ood": 300_000_000,
    "far-pass": 400_000_000,
}
#: The receiver kind (``reset(options={"receiver": ...})``) of each scripted set.
WALKER_KIND = {"walker-id": "id", "walker-ood": "ood", "far-pass": "id"}
WALKERS_PER_SET = 50
#: The far-pass passing lines, m: [q05, q25] of the recorded pelvis y at the transfer over the
#: 848 development-copy recordings with a detected transfer, from ``evaluate.py far-pass``
#: (:mod:`handover_eval.calibration.farpass`); walker i of N passes at
#: ``linspace(low, high, N)[i]``.
FAR_PASS_Y = (-1.275, -1.068)
#: Replays: the held-out half of the split of ``--data`` (folds k//2 .. k-1), or every episode of
#: ``--replay-data``.
REPLAY_FOLDS = 10
REPLAY_SEED = 0
CLOSEDLOOP_SETS: tuple[str, ...] = (
    "walker-id", "walker-ood", "far-pass", "replay-id", "replay-ood"
)
REFERENCE_AGENT = "reactive"
BOOTSTRAP = 2000
BOOTSTRAP_SEED = 0

# --------------------------------------------------------------------------------- quick runs
QUICK_EPISODES = 30
QUICK_OPENLOOP = OpenLoopProtocol(horizon=30, first_query=5, stride=3)
QUICK_FOLDS = 3
QUICK_WALKERS = 1
QUICK_REPLAYS = 2


@dataclass(frozen=True)
class BenchmarkSettings:
    """The protocol values of one run (full, or ``--quick``: never for reported numbers)."""

    quick: bool = False

    @property
    def openloop(self) -> OpenLoopProtocol:
        return QUICK_OPENLOOP if self.quick else OPENLOOP

    @property
    def folds(self) -> int:
        return QUICK_FOLDS if self.quick else OPENLOOP_FOLDS

    @property
    def walkers(self) -> int:
        return QUICK_WALKERS if self.quick else WALKERS_PER_SET

    @property
    def replays_per_fold(self) -> int | None:
        return QUICK_REPLAYS if self.quick else None

    @property
    def replay_folds(self) -> tuple[int, ...]:
        return (0,) if self.quick else tuple(range(REPLAY_FOLDS // 2, REPLAY_FOLDS))

    def to_dict(self) -> dict:
        """Everything of the protocol a run used (goes into result.json and the fingerprint)."""
        return {
            "version": PROTOCOL_VERSION,
            "quick": self.quick,
            "openloop": {
                **self.openloop.to_dict(),
                "folds": self.folds,
                "seed": OPENLOOP_SEED,
            },
            "closedloop": {
                "env": ENV_ID,
                "person": dict(PERSON),
                "theta": list(THETA.as_array()),
                "walkers_per_set": self.walkers,
                "test_seeds": dict(TEST_SEEDS),
                "far_pass_y": list(FAR_PASS_Y),
                "replay_folds": list(self.replay_folds),
                "replays_per_fold": self.replays_per_fold,
                "split": {"folds": REPLAY_FOLDS if not self.quick else QUICK_FOLDS,
                          "seed": REPLAY_SEED},
                "reference": REFERENCE_AGENT,
            },
            "bootstrap": BOOTSTRAP,
            "bootstrap_seed": BOOTSTRAP_SEED,
        }


def far_pass_lines(n: int) -> list[float]:
    """The passing lines of ``n`` far-pass walkers, evenly over :data:`FAR_PASS_Y` (the middle
    for one)."""
    low, high = FAR_PASS_Y
    if n == 1:
        return [round((low + high) / 2, 6)]
    return [round(float(v), 6) for v in np.linspace(low, high, n)]


@dataclass(frozen=True)
class BenchReceiver:
    """One receiver of the closed-loop track: the spec the closed loop knows, the benchmark set,
    the env reset options' receiver kind and the far-pass line (None: the walker's own)."""

    spec: ReceiverSpec
    bench_set: str
    kind: str
    pass_y: float | None = None


def walker_receivers(n: int) -> list[BenchReceiver]:
    """``n`` test-seed walkers of each scripted set (walker-id, walker-ood, far-pass)."""
    out = []
    lines = far_pass_lines(n)
    for name, first in TEST_SEEDS.items():
        kind = WALKER_KIND[name]
        for i in range(n):
            spec = ReceiverSpec(kind, f"{name}-{i:04d}", first + i, is_ood=kind == "ood")
            out.append(BenchReceiver(spec, name, kind, lines[i] if name == "far-pass" else None))
    return out


def replay_receivers(specs: list[ReceiverSpec]) -> list[BenchReceiver]:
    """Replay specs as benchmark receivers (replay-id / replay-ood by the recording's flag)."""
    return [BenchReceiver(s, "replay-ood" if s.is_ood else "replay-id", "replay") for s in specs]


def _digest(obj: object) -> str:
    return hashlib.sha256(
        json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()
    ).hexdigest()[:32]


def receivers_digest(receivers: list[BenchReceiver]) -> str:
    """A hash of who the agent met: set, key, seed, far-pass line, fold, recording flag."""
    return _digest(
        [
            [r.bench_set, r.spec.key, r.spec.seed, r.pass_y, r.spec.fold, r.spec.is_ood]
            for r in receivers
        ]
    )


def fingerprints(
    settings: BenchmarkSettings,
    data: HandoverDataset,
    replay: HandoverDataset | None,
    receivers: list[BenchReceiver] | None,
    tracks: tuple[str, ...],
) -> dict[str, dict]:
    """Per track: the hash that must match for two results to be compared, and its parts."""
    proto = settings.to_dict()
    out: dict[str, dict] = {}
    base = {
        "protocol_version": PROTOCOL_VERSION,
        "data": data.fingerprint(),
        "replay_data": None if replay is None else replay.fingerprint(),
    }
    if "openloop" in tracks:
        parts = {**base, "protocol": {"quick": proto["quick"], **proto["openloop"]}}
        out["openloop"] = {"fingerprint": _digest(parts), **parts}
    if "closedloop" in tracks:
        parts = {
            **base,
            "protocol": {"quick": proto["quick"], **proto["closedloop"]},
            "receivers": receivers_digest(receivers or []),
            "n_receivers": len(receivers or []),
        }
        out["closedloop"] = {"fingerprint": _digest(parts), **parts}
    return out
