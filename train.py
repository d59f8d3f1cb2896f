#!/usr/bin/env python
"""Train the learned baselines and tune Θ with CoSpar: ``python train.py --help``.

A thin script over :mod:`handover_eval.train_cli` (also installed as ``handover-train``).
"""

import sys

from handover_eval.train_cli import main

if __name__ == "__main__":
    sys.exit(main())
