"""The RL policy that ships with the package: ``baselines/rl/policy/`` (``config.json`` and
``model.safetensors``, as ``train.py rl`` writes them; its training state is not shipped).

``evaluate.py benchmark --agent rl`` and ``evaluate.py closed-loop --agents rl`` score it with no
training. It loads through the same safe loader as any checkpoint
(:meth:`baselines.rl.agent.RLAgent.load`: nothing unpickled, every field and tensor checked), and
as any RL agent it refuses the recordings it trained on and the training seeds
(:meth:`~baselines.rl.agent.RLAgent.check_receiver`). Its ``config.json`` records the
configuration, the receivers it trained on, the commit and the command that trained it
(``versions``); docs/rl.md says which run it is and how it was chosen.
"""

from __future__ import annotations

from pathlib import Path

from baselines.checkpoint_io import CheckpointError
from baselines.rl.agent import RLAgent
from handover_env.config import HandoverParams

#: The shipped policy's folder.
SHIPPED = Path(__file__).resolve().parent / "policy"


def load_shipped(params: HandoverParams | None = None, folder: Path = SHIPPED) -> RLAgent:
    """The shipped policy as an agent (Θ's t_f goes to its base); a CheckpointError naming the
    folder when it is missing or does not load."""
    if not (folder / "config.json").is_file():
        raise CheckpointError(f"{folder}: the shipped RL policy is missing (an install without "
                              "the package data?)")
    return RLAgent.load(folder, params=params)
