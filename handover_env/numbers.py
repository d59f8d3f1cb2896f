"""The one check of every number a user passes in: walker fields, person settings, reset options
and sensor overrides (:func:`checked_number`). A value is accepted only if it is a real number
(an int or float, numpy's included; a bool is not a number), finite and within its stated range;
otherwise one ``ValueError`` names the setting, the range, its unit and where the range comes from.
"""

from __future__ import annotations

import math

import numpy as np


def is_real_number(value: object) -> bool:
    """An int or a float (numpy's too), not a bool."""
    return not isinstance(value, (bool, np.bool_)) and isinstance(
        value, (int, float, np.integer, np.floating)
    )


def checked_number(
    label: str, value: object, lo: float, hi: float, unit: str = "", why: str = ""
) -> float:
    """``value`` as a float if it is a real, finite number in ``[lo, hi]``.

    Args:
        label: how the message names the setting, e.g. ``"walker pass_y"``.
        value: what the user gave.
        lo, hi: the range (inclusive).
        unit: the range's unit, for the message.
        why: where the range comes from, for the message.

    Raises:
        ValueError: not a real number, not finite, or outside the range.
    """
    if not is_real_number(value):
        raise ValueError(f"{label} must be a number, got {value!r:.80}")
    try:
        x = float(value)  # type: ignore[arg-type]
    except OverflowError:  # an int too large for a float (e.g. 10**400)
        raise ValueError(
            f"{label} must be in [{lo:.6g}, {hi:.6g}]{' ' + unit if unit else ''}"
            f"{f' ({why})' if why else ''}, got an integer of about "
            f"{int(int(value).bit_length() * math.log10(2)) + 1} digits"  # type: ignore[call-overload]
        ) from None
    if not (math.isfinite(x) and lo <= x <= hi):
        raise ValueError(
            f"{label} must be {'' if math.isfinite(x) else 'finite and '}in [{lo:.6g}, {hi:.6g}]"
            f"{' ' + unit if unit else ''}{f' ({why})' if why else ''}, got {value!r:.80}"
        )
    return x
