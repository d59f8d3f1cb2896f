"""A one-line error naming the pip extra that a module needs and that is not installed.

``pip install handover_env`` is the env and the data tools alone; the learned baselines need
``[baselines]`` (torch, safetensors, LeRobot), the mp4 writers ``[video]`` (see ``pyproject.toml``).
A module that needs an extra imports it through :func:`missing_extra`::

    try:
        import torch
    except ModuleNotFoundError as exc:
        raise missing_extra("baselines", exc, __name__) from None
"""

from __future__ import annotations


class MissingExtraError(ImportError):
    """A dependency of an optional extra is not installed; the message names the extra."""


def missing_extra(extra: str, exc: ModuleNotFoundError, needed_by: str) -> MissingExtraError:
    """The error to raise when ``needed_by`` cannot import a dependency of ``extra``.

    Args:
        extra: the pip extra that provides the dependency (e.g. ``"baselines"``).
        exc: the ``ModuleNotFoundError`` of the failed import (its ``name`` is the missing module).
        needed_by: the module that needs it (usually ``__name__``).
    """
    missing = (exc.name or str(exc)).split(".")[0]
    return MissingExtraError(
        f"{needed_by} needs the [{extra}] extra ({missing} is not installed): "
        f"pip install 'handover_env[{extra}]'",
        name=exc.name,
    )
