"""The calibration of the simulated person against the recordings of the public dataset: analysis,
not simulation (``handover-data transfer-stats``, ``walk-stats``, ``sensing``, ``reach-spread``,
``calibrated-range`` and ``grasp-height``, and ``evaluate.py far-pass``).

* the transfer and the reach onset in a recording are detected by :mod:`handover_env.data.detect`
  (the simulator replays a recorded person's own reach with it); :mod:`.release`: the giver's
  release and the arm drawn back;
* :mod:`.measures`: the per-recording measures at those events;
* :mod:`.decisions`: the person's decision rules checked on the recordings, and the reach fit;
* :mod:`.report`: the run over a dataset folder (calibration and held-out halves, quantiles);
* :mod:`.markdown`, :mod:`.figures`: the report's Markdown table and PNG figures;
* :mod:`.walks`, :mod:`.walks_report`: recorded and scripted walks measured alike;
* :mod:`.sensing`: the camera model's numbers (jitter, hand error, re-fit bursts);
* :mod:`.farpass`: the far-pass stress set's lateral range;
* :mod:`.reach_spread`: the reach's giver-dependent line and the per-person offsets;
* :mod:`.calibrated_range`: the range of walks the person was calibrated on;
* :mod:`.grasp_height`: the recorded arm at the transfer: the hand below the object's centre
  (the evidence of the person's ``grasp_below``) and the elbow's swivel direction (the arm IK's
  elbow pole);
* :mod:`.grasp_height_report`: its page and the command's runner (writes the JSON and the page).

Every file goes through :mod:`handover_eval.reporting`'s writers. The Markdown pages quote the
command and module paths that generated ``docs/calibration/`` when they lived in
``handover_env/data/``, so that a rerun writes the same bytes.
"""
