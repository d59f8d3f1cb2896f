"""The benchmark of dynamic robot-to-human handover (protocol v2, docs/benchmark.md).

* :mod:`.protocol`: the versioned protocol constants, the receivers of the closed-loop track and
  the fingerprints of a run.
* :mod:`.plugin`: the scored agent, a built-in name or a user's factory (``PKG.MODULE:FACTORY``
  or ``path/to/file.py:FACTORY``).
* :mod:`.outcomes`: first-failure attribution and the event flags of a closed-loop episode.
* :mod:`.open_loop`, :mod:`.closed_loop`: the two tracks' runs (values, no files).
* :mod:`.tables`: the metrics and tables from per-episode rows (the run and ``rescore`` share it).
* :mod:`.files`: result.json and the per-episode CSVs, written and read back with every field
  checked (reading runs no code).
* :mod:`.leaderboard`: the ranked table and figure from result files.
* :mod:`.run`: a whole benchmark run.

The far-pass stress set's lateral range is derived from the recordings by
:mod:`handover_eval.calibration.farpass` (``evaluate.py far-pass``).
"""
