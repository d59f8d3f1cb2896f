"""Preference learning on the env: CoSpar tuning of Θ with simulated participants
(:mod:`.tuning`, walks batched by :mod:`.batch`), the recovery check against known optima
(:mod:`.check`) and the paper's user study H1-H3 with simulated participants (:mod:`.study`,
written by :mod:`.study_report`)."""
