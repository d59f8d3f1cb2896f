"""The receiver-calibration analysis of the public dataset (``python -m handover_env.data
transfer-stats``): when and where the object changes hands, and how the receiver moves.

* :mod:`.detect`: the transfer, reach onset, giver release and the arm drawn back in a recording;
* :mod:`.measures`: the per-recording measures at those events;
* :mod:`.report`: the run over a dataset folder (calibration and held-out halves, quantiles);
* :mod:`.markdown`, :mod:`.figures`: the report's Markdown table and PNG figures.
"""
