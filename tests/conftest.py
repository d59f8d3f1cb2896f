"""The test families' shared root.

The tests live in one folder per family (``security/``, ``env/``, ``person/``, ``data/``,
``agents/``, ``baselines/``, ``eval/``, ``project/``). The helpers that several families use stay
here and are imported by bare name: ``crafted`` (hostile files built in a temporary folder),
``baselines_toy`` (a tiny synthetic dataset for the learned baselines), ``quadratic_users``
(closed-form preference users for CoSpar) and ``planted`` (a checkpoint commit planted out of its
folder, and the check that nothing moved). This folder is put on ``sys.path`` once, here.
"""

from __future__ import annotations

import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
if str(TESTS) not in sys.path:
    sys.path.insert(0, str(TESTS))
