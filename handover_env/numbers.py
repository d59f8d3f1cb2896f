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


def fits_float(value: object) -> bool:
    """False for a number ``float()`` cannot hold (an int beyond ~1.8e308); True otherwise."""
    try:
        float(value)  # type: ignore[arg-type]
    except OverflowError:
        return False
    except (TypeError, ValueError):
        return True
    return True


def shown(value: object) -> str:
    """``value`` for an error message: its repr cut at 80 characters, or an integer too large for
    a float by its number of digits (its repr may not even be allowed: ``sys.int_info``)."""
    if is_real_number(value) and not fits_float(value):
        digits = int(abs(int(value)).bit_length() * math.log10(2)) + 1  # type: ignore[call-overload]
        return f"an integer of about {digits} digits"
    return f"{value!r:.80}"


def checked_number(
    label: str, value: object, lo: float, hi: float, unit: str = "", why: str = ""
) -> float:
    """``value`` as a float if it is a real, finite number in ``[lo, hi]``.

    An integer too large for a float counts as not finite.

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
    x = float(value) if fits_float(value) else math.inf  # type: ignore[arg-type]
    if not (math.isfinite(x) and lo <= x <= hi):
        raise ValueError(
            f"{label} must be {'' if math.isfinite(x) else 'finite and '}in [{lo:.6g}, {hi:.6g}]"
            f"{' ' + unit if unit else ''}{f' ({why})' if why else ''}, got {shown(value)}"
        )
    return x
