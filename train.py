#!/usr/bin/env python
"""Train the learned baselines and tune Θ with CoSpar: ``python train.py --help``.

A thin script over :mod:`handover_eval.cli.train` (also installed as ``handover-train``).
"""

import sys

from handover_eval.cli.train import main

if __name__ == "__main__":
    sys.exit(main())
