"""``bench/person_check.py``'s interval of the reach median's difference (issue 35)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location(
    "person_check", Path(__file__).parents[2] / "bench" / "person_check.py")
person_check = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(person_check)


def test_a_constant_shift_is_the_difference_and_its_whole_interval():
    rec = np.linspace(0.3, 0.7, 35)
    d, lo, hi = person_check.median_difference_ci(rec + 0.03, rec)
    assert d == pytest.approx(0.03) and lo == pytest.approx(0.03) and hi == pytest.approx(0.03)


def test_the_interval_holds_the_difference_and_is_seeded():
    rng = np.random.default_rng(1)
    rec = rng.normal(0.49, 0.09, 35)
    sim = rec - 0.03 + rng.normal(0, 0.05, 35)
    d, lo, hi = person_check.median_difference_ci(sim, rec)
    assert d == pytest.approx(np.median(sim) - np.median(rec))
    assert lo < d < hi and hi - lo < 0.2
    assert person_check.median_difference_ci(sim, rec) == (d, lo, hi)
    assert all(np.isnan(person_check.median_difference_ci(sim[:1], rec[:1])))
