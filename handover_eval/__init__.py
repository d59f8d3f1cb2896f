"""Evaluation: the open-loop RMS protocol every method shares (:mod:`.openloop.protocol`) and
result tables."""

from handover_eval.openloop.protocol import (
    EpisodeRecord,
    OpenLoopProtocol,
    episode_errors,
    episode_rms,
    evaluate_openloop,
    kfold_rms,
    query_times,
    summarise,
)

__all__ = [
    "EpisodeRecord",
    "OpenLoopProtocol",
    "episode_errors",
    "episode_rms",
    "evaluate_openloop",
    "kfold_rms",
    "query_times",
    "summarise",
]
