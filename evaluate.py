#!/usr/bin/env python
"""Reproduce the paper's simulation results: ``python evaluate.py --help``.

A thin script over :mod:`handover_eval.evaluate_cli` (also installed as ``handover-evaluate``).
"""

import sys

from handover_eval.evaluate_cli import main

if __name__ == "__main__":
    sys.exit(main())
