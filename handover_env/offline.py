"""Keep the Hugging Face libraries off the network, for the command-line entry points only.

LeRobot reads datasets through ``huggingface_hub`` and ``datasets``, which would try the Hub for a
file they do not find locally. Everything this project reads is local, so every command
(``train.py``, ``evaluate.py``, ``handover-data``, the benches) calls
:func:`hub_offline` first. Library modules never do: importing them leaves the process's
environment alone, and a program that imports them decides for itself.
"""

from __future__ import annotations

import os

OFFLINE_VARIABLES = ("HF_HUB_OFFLINE", "HF_DATASETS_OFFLINE")


def hub_offline() -> None:
    """Set ``HF_HUB_OFFLINE=1`` and ``HF_DATASETS_OFFLINE=1`` unless the caller already set them.

    Call it before ``lerobot``, ``huggingface_hub`` or ``datasets`` is imported: they read the
    variables once, at import.
    """
    for name in OFFLINE_VARIABLES:
        os.environ.setdefault(name, "1")
