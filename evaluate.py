#!/usr/bin/env python
"""Reproduce the paper's simulation results: ``python evaluate.py --help``.

A thin script over :mod:`handover_eval.cli.evaluate` (also installed as ``handover-evaluate``).
"""

import sys

from handover_eval.cli.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
