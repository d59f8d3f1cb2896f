"""The command lines: argparse and dispatch only.

:mod:`.evaluate` (``evaluate.py``, ``handover-evaluate``) and :mod:`.train` (``train.py``,
``handover-train``) are the two entry points; :mod:`.closedloop`, :mod:`.user_study` and
:mod:`.preference` add their subcommands; :mod:`.data` is ``handover-data`` (datasets and the
person's calibration); :mod:`.args` holds the argument types and the backend
flags they share. No module outside ``cli/`` imports it, and every computation is imported lazily
so ``--help`` stays fast.
"""
