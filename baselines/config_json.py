"""Config dataclasses from checkpoint JSON: every field present and of its exact JSON type.

``"no"`` is not a bool, a float is not an int, a bool is not an int, a list holds at most
:data:`MAX_LIST` items (checked before its items: a crafted 16 MB list of millions of numbers
is refused at once); a refused field is a :class:`~baselines.checkpoint_io.CheckpointError`
naming the file and the field.
"""

from __future__ import annotations

import math
import typing
from dataclasses import fields
from typing import Any

from baselines.checkpoint_io import CheckpointError

#: The most items a list field of a config may hold (our longest: a few layer widths).
MAX_LIST = 1000


def json_type_ok(value: Any, hint: Any) -> bool:
    """Is ``value`` (read from JSON) of the type ``hint``: bool, int, float (finite), str, a JSON
    object (``dict``), ``tuple[X, ...]`` (a JSON list) or ``X | None``? A bool is not an int."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if type(None) in args:
        return value is None or any(json_type_ok(value, a) for a in args if a is not type(None))
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return (
            isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        )
    if hint is str:
        return isinstance(value, str)
    if origin is dict or hint is dict:  # a JSON object; its contents are the config's to check
        return isinstance(value, dict) and all(isinstance(k, str) for k in value)
    if origin is tuple:  # tuple[int, ...] stored as a JSON list, of at most MAX_LIST items
        return (isinstance(value, (list, tuple)) and len(value) <= MAX_LIST
                and all(json_type_ok(v, args[0]) for v in value))
    return False


def config_from_dict(cls: type, d: Any, source: str, ignore: frozenset[str] = frozenset()) -> Any:
    """``cls(**d)`` for a config dataclass, refusing missing, unknown or mistyped fields.

    Args:
        cls: the dataclass (its fields are int, float, bool, str or tuple[int, ...]).
        d: the dict read from JSON.
        source: the file, for messages.
        ignore: fields that may be absent (filled by the caller).
    """
    if not isinstance(d, dict):
        raise CheckpointError(f"{source}: config must be a JSON object, got {type(d).__name__}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(d) - set(names))
    missing = sorted(set(names) - set(d) - ignore)
    if unknown or missing:
        raise CheckpointError(
            f"{source}: config fields do not match (unknown {unknown}, missing {missing})"
        )
    for name in names:
        if name in d and not json_type_ok(d[name], hints[name]):
            value = d[name]
            if isinstance(value, list) and len(value) > MAX_LIST:
                raise CheckpointError(f"{source}: config field {name} is a list of {len(value):,} "
                                      f"items, more than {MAX_LIST}")
            shown = repr(value)
            shown = shown if len(shown) <= 60 else shown[:57] + "..."
            raise CheckpointError(
                f"{source}: config field {name} = {shown} is not a "
                f"{getattr(hints[name], '__name__', hints[name])}"
            )
    try:
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})
    except (ValueError, TypeError) as exc:
        raise CheckpointError(f"{source}: invalid config ({exc})") from None
