"""Closed-loop evaluation: every agent hands the bottle to the same simulated receivers.

:mod:`.run` computes (receivers from :mod:`.receivers`, agents from
:mod:`handover_eval.roster`, fold models from :mod:`.models`, jobs in :mod:`.worker`, each
episode by :mod:`handover_eval.episodes`), :mod:`.stats` and :mod:`.report` turn the episode
rows into aggregates and paired comparisons, :mod:`.markdown` and :mod:`.plot` into tables and
figures, and :mod:`.output` writes the files. :mod:`.theta_sweep` runs one agent at every value
of each Θ parameter on the same receivers.
"""
