"""``make demo``: the paper's question (Sec. V-C, H2), dynamic vs static handover, on the same
seeded walkers, side by side.

* :mod:`.run`: the fixed walkers, the two sides (the SPGP planner in ``DynamicHandover-v0``, the
  static baseline in ``StaticHandover-v0``), each episode scored as the benchmark scores it;
* :mod:`.view`: the free camera that frames the handover;
* :mod:`.caption`: what each side's caption says, drawn onto the frame;
* :mod:`.report`: the side-by-side frames and the summary (success and median handover time);
* :mod:`.output`: the mp4, the still, the Markdown and CSV summary.

The command line is :mod:`handover_eval.cli.demo` (``python -m handover_eval.cli.demo``,
``handover-demo``).
"""
