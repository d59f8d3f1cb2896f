"""The values of a result.json checked against each other (after :mod:`.files` checked each
field's type).

A result's numbers must be ones a benchmark run can write (:mod:`.tables`):

* closed loop, per set: ``n >= 1``; ``0 <= k <= n``; the success rate is ``k / n`` and its CI the
  Wilson interval of ``k`` and ``n`` (:func:`handover_eval.closedloop.stats.wilson_interval`); the
  first failures add up to ``n - k``; the handover time is a median over at most ``k`` successes;
  paired differences are over at most ``n`` receivers, a success difference within [-1, 1];
  ``all`` adds up the sets (``n``, ``k``, every first failure);
* open loop: every error, CI bound and fold mean >= 0, a fold std >= 0; ``all`` counts the
  episodes of ``id`` and ``ood``;
* every CI: null exactly when its ``n`` is 0, and then all of it null; otherwise
  ``low <= value <= high`` (to 1e-9 of the value, the rounding of a bootstrap quantile);
* the closed loop's ``all.n`` is at most the rows of its episode file.

:func:`value_problem` returns the first field that breaks one of these, as
``"<field path>: <what is wrong>"``, or None.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from handover_eval.benchmark.outcomes import CHECKS
from handover_eval.benchmark.protocol import CLOSEDLOOP_SETS, OPENLOOP_METRICS
from handover_eval.closedloop.stats import wilson_interval

ALL = "all"
REL_TOL = 1e-9


class _Bad(Exception):
    """One broken relation: the field's path and what is wrong."""


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= REL_TOL * max(1.0, abs(a), abs(b))


def _fail(where: str, what: str) -> None:
    raise _Bad(f"{where}: {what}")


def _ci(c: Mapping[str, Any], where: str, key: str = "value", low: float | None = None,
        high: float | None = None, n_max: int | None = None) -> None:
    """A CI ``{key, low, high, n}``: null exactly when n = 0, ordered, within [low, high]."""
    n, v, lo, hi = c["n"], c[key], c["low"], c["high"]
    if n_max is not None and n > n_max:
        _fail(f"{where}.n", f"{n} is more than the {n_max} it is counted over")
    if n == 0:
        if (v, lo, hi) != (None, None, None):
            _fail(where, f"n is 0 but {key}, low and high are not all null")
        return
    for name, x in ((key, v), ("low", lo), ("high", hi)):
        if x is None:
            _fail(f"{where}.{name}", f"null although n is {n}")
        if (low is not None and x < low and not _close(x, low)) or (
                high is not None and x > high and not _close(x, high)):
            _fail(f"{where}.{name}", f"{x!r} is outside [{low}, {high}]")
    if not (lo <= v or _close(lo, v)) or not (v <= hi or _close(v, hi)):
        _fail(where, f"not low <= {key} <= high ({lo!r}, {v!r}, {hi!r})")


def _closed_set(m: Mapping[str, Any], where: str) -> None:
    n, s = m["n"], m["success"]
    if n < 1:
        _fail(f"{where}.n", f"{n}: a set holds at least one episode")
    k = s["k"]
    if k > n:
        _fail(f"{where}.success.k", f"{k} successes out of n = {n}")
    for name in ("value", "low", "high"):
        if s[name] is None:
            _fail(f"{where}.success.{name}", "null although n >= 1")
    if not _close(s["value"], k / n):
        _fail(f"{where}.success.value", f"{s['value']!r} is not k / n = {k}/{n}")
    lo, hi = wilson_interval(k, n)
    if not (_close(s["low"], lo) and _close(s["high"], hi)):
        _fail(f"{where}.success", f"[{s['low']!r}, {s['high']!r}] is not the Wilson interval of "
              f"{k}/{n} ([{lo:.6g}, {hi:.6g}])")
    failed = sum(m["first_failure"].values())
    if failed != n - k:
        _fail(f"{where}.first_failure", f"counts {failed} failures, n - k = {n - k}")
    _ci(m["handover_time"], f"{where}.handover_time", low=0.0, n_max=k)
    if m["paired"] is not None:
        _ci(m["paired"]["success"], f"{where}.paired.success", "diff", -1.0, 1.0, n_max=n)
        _ci(m["paired"]["handover_time"], f"{where}.paired.handover_time", "diff", n_max=n)


def _closedloop(metrics: Mapping[str, Any], rows: int, where: str) -> None:
    if ALL not in metrics:
        _fail(where, "lacks the set 'all'")
    for name, m in metrics.items():
        _closed_set(m, f"{where}.{name}")
    sets = [metrics[s] for s in CLOSEDLOOP_SETS if s in metrics]
    total = metrics[ALL]
    for what, get in (("n", lambda m: m["n"]), ("success.k", lambda m: m["success"]["k"]),
                      *((f"first_failure.{c}", lambda m, c=c: m["first_failure"][c])
                        for c in CHECKS)):
        if get(total) != sum(get(m) for m in sets):
            _fail(f"{where}.all.{what}", f"{get(total)} is not the sum over the sets "
                  f"({sum(get(m) for m in sets)})")
    if total["n"] > rows:
        _fail(f"{where}.all.n", f"{total['n']} episodes but the episode file has {rows} rows")


def _openloop(metrics: Mapping[str, Any], where: str) -> None:
    if ALL not in metrics:
        _fail(where, "lacks the set 'all'")
    for name, m in metrics.items():
        for metric, c in m.items():
            w = f"{where}.{name}.{metric}"
            _ci(c, w, low=0.0)
            if (c["fold_mean"] is None) != (c["n"] == 0):
                _fail(f"{w}.fold_mean", "null exactly when n is 0")
            for key in ("fold_mean", "fold_std"):
                if c[key] is not None and c[key] < 0:
                    _fail(f"{w}.{key}", f"{c[key]!r} is negative")
    for metric in OPENLOOP_METRICS:
        parts = [metrics[s][metric]["n"] for s in ("id", "ood") if s in metrics]
        if metrics[ALL][metric]["n"] != sum(parts):
            _fail(f"{where}.all.{metric}.n", f"{metrics[ALL][metric]['n']} is not the episodes "
                  f"of id and ood ({sum(parts)})")


def value_problem(data: Mapping[str, Any]) -> str | None:
    """The first relation ``data`` (a result.json whose fields are each well typed) breaks, as
    ``"<field>: <what>"``; None when its values agree with each other (module docstring)."""
    try:
        for track, entry in data["episodes"].items():
            if entry["rows"] < 1:
                _fail(f"episodes.{track}.rows", "an episode file holds at least one row")
        metrics = data["metrics"]
        if "closedloop" in metrics:
            _closedloop(metrics["closedloop"], data["episodes"]["closedloop"]["rows"],
                        "metrics.closedloop")
        if "openloop" in metrics:
            _openloop(metrics["openloop"], "metrics.openloop")
    except _Bad as bad:
        return str(bad)
    return None
