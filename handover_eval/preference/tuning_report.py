"""Tables, figures and files of a CoSpar run (:func:`.tuning.run_preference`): the posterior
marginals, the Θ̂ line and :func:`save_run`'s folder."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.cospar import THETA_NAMES, CoSpar
from agents.participants import Participant
from handover_env.config import HandoverParams
from handover_eval.preference.tuning import PAPER_THETA, PreferenceConfig, PreferenceResult
from handover_eval.reporting import write_csv, write_png, write_text


def posterior_marginals(learner: CoSpar) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per parameter: (values, mean over the other parameters of the posterior mean, of its sd)."""
    shape = learner.config.points_per_dim
    mean = learner.f_hat.reshape(shape)
    sd = np.sqrt(np.clip(np.diag(learner.cov), 0.0, None)).reshape(shape)
    out = []
    for k, (lo, hi) in enumerate(learner.config.ranges):
        axes = tuple(j for j in range(4) if j != k)
        out.append((np.linspace(lo, hi, shape[k]), mean.mean(axis=axes), sd.mean(axis=axes)))
    return out


def marginals_figure(learner: CoSpar, theta_hat: HandoverParams, title: str) -> Any:
    """The posterior mean of the utility, averaged over the other three parameters, per
    parameter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = ("K (N/m)", "B (N s/m)", "t_f (s)", "f_r (N)")
    fig, axes = plt.subplots(1, 4, figsize=(13, 3.2), sharey=True)
    for k, (ax, (x, m, s)) in enumerate(zip(axes, posterior_marginals(learner))):
        ax.plot(x, m, "o-", color="C0")
        ax.fill_between(x, m - s, m + s, color="C0", alpha=0.2, label="posterior mean ± sd")
        ax.axvline(theta_hat.as_array()[k], color="C3", label="our Θ̂")
        ax.axvline(PAPER_THETA[k], color="0.4", ls="--", label="paper's Θ̂")
        ax.set_xlabel(labels[k])
    axes[0].set_ylabel("utility (posterior mean,\naveraged over the others)")
    axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle(title + " (simulated participants)", fontsize=10)
    fig.tight_layout()
    return fig


def theta_line(theta: HandoverParams) -> str:
    k, b, tf, fr = theta.as_array()
    return f"[K {k:.1f}, B {b:.1f}, t_f {tf:.2f}, f_r {fr:.1f}]"


def save_run(
    result: PreferenceResult,
    participants: Sequence[Participant],
    config: PreferenceConfig,
    out: Path,
) -> list[Path]:
    """theta_hat.json, history.csv, preferences.csv, participants.csv, posterior_marginals.png."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [
        out / "theta_hat.json",
        out / "history.csv",
        out / "preferences.csv",
        out / "participants.csv",
        out / "posterior_marginals.png",
    ]
    iters = config.iterations
    record = {
        "source": "simulated participants (agents/participants.py), not people",
        "theta_hat": dict(zip(THETA_NAMES, result.theta_hat.as_array())),
        "theta_hat_whole_grid": dict(zip(THETA_NAMES, result.theta_hat_grid.as_array())),
        "paper_theta_hat": dict(zip(THETA_NAMES, PAPER_THETA)),
        "participants": [p.pid for p in participants],
        "iterations": iters,
        "walks": config.walks,
        "agent": config.agent,
        "receiver": config.receiver,
        "sensing": config.sensing,
        "grid": list(config.cospar.points_per_dim),
        "preferences": len(result.preferences),
        "episodes": result.episodes,
        "episode_seconds": result.episode_seconds,
        "wall_seconds": result.seconds,
        "seconds_per_iteration": result.seconds / iters,
    }
    write_text(json.dumps(record, indent=1), paths[0])
    write_csv(result.history, paths[1])
    write_csv(result.preferences, paths[2])
    write_csv([p.describe() for p in participants], paths[3])
    who = (
        f"participant {participants[0].pid}"
        if len(participants) == 1
        else f"{len(participants)} participants pooled"
    )
    write_png(
        marginals_figure(
            result.learner, result.theta_hat, f"CoSpar posterior after {iters} iterations, {who}"
        ),
        paths[4],
        dpi=110,
    )
    return paths
