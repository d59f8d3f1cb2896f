"""Open-loop evaluation (paper Sec. V-A): the shared RMS protocol (:mod:`.protocol`), the runs of
Table I, the sample-efficiency and trade-off sweeps (:mod:`.experiments`) and their tables and
figures (:mod:`.report`)."""
