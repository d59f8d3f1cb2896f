"""``train.py rl``: training the RL handover policy (run / report / output).

* :mod:`.run`: the training receivers from the dataset (replays of the training folds only),
  one seed's run, several seeds through :mod:`handover_eval.backend`.
* :mod:`.report`: the learning-curve figure and the console summary.
* :mod:`.output`: ``train_log.csv``, ``learning_curve.png``, ``train_summary.json``.
"""
