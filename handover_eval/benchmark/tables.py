"""The benchmark's metrics and tables, computed from per-episode rows only.

A run writes its per-episode CSVs first and then builds every table from the rows read back from
them (:mod:`.files`); ``evaluate.py rescore`` does exactly the same, so its tables are the run's,
byte for byte, and no table holds a number that is not in an episode file.

Closed loop, per agent and receiver set (and ``all`` pooled): the success rate with its 95 %
Wilson interval, the first failure of every failed episode (:mod:`.outcomes`), the median
handover time over the successes with a percentile bootstrap CI, and, for every agent but the
reference, the paired differences against the reactive reference on the same receivers (success:
mean of the 0/1 differences; handover time: median over the receivers both handed over to;
bootstrap CIs resampling receivers; :mod:`handover_eval.closedloop.stats`). Open loop, per agent
and test set (ID, OOD, all): every metric's mean over the test episodes with a bootstrap CI of
the mean, and Table I's reading, the mean ± std over folds of the per-fold means.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from handover_eval.benchmark.outcomes import CHECKS
from handover_eval.benchmark.protocol import (
    CLOSEDLOOP_SETS,
    OPENLOOP_METRICS,
    REFERENCE_AGENT,
)
from handover_eval.closedloop.stats import (
    bootstrap_ci,
    ci_excludes_zero,
    pair_up,
    paired_difference,
    stable_seed,
    wilson_interval,
)
from handover_eval.reporting import markdown_table

ALL = "all"


def _finite(values: Sequence[float]) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    return v[np.isfinite(v)]


def _ci(values: Sequence[float], stat: str, n_boot: int, seed: int) -> dict[str, float | int]:
    v = _finite(values)
    est, lo, hi = bootstrap_ci(v, stat, n_boot, seed)
    return {"value": est, "low": lo, "high": hi, "n": int(v.size)}


def _paired(
    mine: Sequence[dict], ref: Sequence[dict], column: str, stat: str, n_boot: int, seed: int
) -> dict[str, float | int]:
    a = {(r["set"], r["receiver"]): float(r[column]) for r in mine}
    b = {(r["set"], r["receiver"]): float(r[column]) for r in ref}
    _, x, y = pair_up(a, b)
    d = paired_difference(x, y, stat, n_boot, seed)
    return {"diff": d.diff, "low": d.low, "high": d.high, "n": d.n}


def _by(rows: Sequence[dict], column: str) -> dict[Any, list[dict]]:
    """Rows grouped by ``column`` in one pass: values in first-seen order, rows in file order."""
    out: dict[Any, list[dict]] = {}
    for r in rows:
        out.setdefault(r[column], []).append(r)
    return out


def _groups(rows: Sequence[dict], sets: Sequence[str]) -> dict[tuple[str, str], list[dict]]:
    """(agent, set) -> rows, agents in first-seen order, sets in ``sets`` order, then ``all``."""
    out: dict[tuple[str, str], list[dict]] = {}
    for agent, mine in _by(rows, "agent").items():
        per_set = _by(mine, "set")
        for s in sets:
            if s in per_set:
                out[(agent, s)] = per_set[s]
        out[(agent, ALL)] = mine
    return out


def closedloop_metrics(rows: Sequence[dict], n_boot: int, seed: int,
                       reference: str = REFERENCE_AGENT) -> dict[str, dict[str, Any]]:
    """agent -> set -> metrics (module docstring), each agent paired against ``reference`` (the
    protocol's, or another agent of the rows: ``rescore --reference``); rows as
    :func:`.files.read_episodes` gives."""
    groups = _groups(rows, CLOSEDLOOP_SETS)
    out: dict[str, dict[str, Any]] = {}
    for (agent, rset), mine in groups.items():
        n = len(mine)
        k = sum(1 for r in mine if r["success"])
        lo, hi = wilson_interval(k, n)
        times = [r["handover_time"] for r in mine if r["success"]]
        entry: dict[str, Any] = {
            "n": n,
            "success": {"value": k / n, "low": lo, "high": hi, "k": k},
            "first_failure": {c: sum(1 for r in mine if r["first_failure"] == c) for c in CHECKS},
            "handover_time": _ci(times, "median", n_boot, stable_seed(agent, rset, "t", base=seed)),
            "paired": None,
        }
        ref = groups.get((reference, rset))
        if agent != reference and ref is not None:
            for r in mine + ref:
                r["_success01"] = 1.0 if r["success"] else 0.0
                r["_time_ok"] = r["handover_time"] if r["success"] else math.nan
            entry["paired"] = {
                "success": _paired(mine, ref, "_success01", "mean", n_boot,
                                   stable_seed(agent, rset, "ps", base=seed)),
                "handover_time": _paired(mine, ref, "_time_ok", "median", n_boot,
                                         stable_seed(agent, rset, "pt", base=seed)),
            }
            for r in mine + ref:
                del r["_success01"], r["_time_ok"]
        out.setdefault(agent, {})[rset] = entry
    return out


def openloop_metrics(rows: Sequence[dict], n_boot: int, seed: int) -> dict[str, dict[str, Any]]:
    """agent -> set (id, ood, all) -> metric -> value, CI, n, fold mean and std."""
    out: dict[str, dict[str, Any]] = {}
    for agent, mine in _by(rows, "agent").items():
        for rset, keep in (("id", False), ("ood", True), (ALL, None)):
            chosen = [r for r in mine if keep is None or r["is_ood"] == keep]
            if not chosen:
                continue
            entry = {}
            folds = _by(chosen, "fold").values()
            for metric in OPENLOOP_METRICS:
                ci = _ci([r[metric] for r in chosen], "mean", n_boot,
                         stable_seed(agent, rset, metric, base=seed))
                per_fold = []
                for fold_rows in folds:
                    v = _finite([r[metric] for r in fold_rows])
                    if v.size:
                        per_fold.append(float(v.mean()))
                fold_mean = float(np.mean(per_fold)) if per_fold else math.nan
                fold_std = float(np.std(per_fold, ddof=1)) if len(per_fold) > 1 else math.nan
                entry[metric] = {**ci, "fold_mean": fold_mean, "fold_std": fold_std}
            out.setdefault(agent, {})[rset] = entry
    return out


# ---------------------------------------------------------------------------------- rendering
def _f(v: float | None, digits: int, scale: float = 1.0) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{scale * v:.{digits}f}"


def success_text(s: dict, n: int) -> str:
    """'93 % [84, 97] (28/30)'."""
    return f"{_f(s['value'], 0, 100)} % [{_f(s['low'], 0, 100)}, {_f(s['high'], 0, 100)}] " \
        f"({s['k']}/{n})"


def ci_text(c: dict | None, digits: int, key: str = "value") -> str:
    """'1.82 [1.75, 1.90]' or '–'."""
    if c is None or c.get(key) is None or not math.isfinite(c[key]):
        return "–"
    star = " *" if key == "diff" and ci_excludes_zero(c["low"], c["high"]) else ""
    sign = "+" if key == "diff" else ""
    return (f"{c[key]:{sign}.{digits}f} [{c['low']:{sign}.{digits}f}, "
            f"{c['high']:{sign}.{digits}f}]{star}")


def failures_text(ff: dict[str, int]) -> str:
    parts = [f"{c} {n}" for c, n in ff.items() if n]
    return ", ".join(parts) or "–"


def closedloop_table_rows(metrics: dict[str, dict[str, Any]]) -> list[dict]:
    """One flat row per agent and set (the CSV), in the metrics' order."""
    rows = []
    for agent, sets in metrics.items():
        for rset, m in sets.items():
            row = {"agent": agent, "set": rset, "n": m["n"], "successes": m["success"]["k"]}
            row.update({f"success_{k}": m["success"][k] for k in ("value", "low", "high")})
            row.update({f"first_failure_{c}": n for c, n in m["first_failure"].items()})
            row.update({f"handover_time_{k}": v for k, v in m["handover_time"].items()})
            for name in ("success", "handover_time"):
                p = (m["paired"] or {}).get(name) or {}
                row.update({f"paired_{name}_{k}": p.get(k, math.nan)
                            for k in ("diff", "low", "high", "n")})
            rows.append(row)
    return rows


def openloop_table_rows(metrics: dict[str, dict[str, Any]]) -> list[dict]:
    rows = []
    for agent, sets in metrics.items():
        for rset, m in sets.items():
            row: dict[str, Any] = {"agent": agent, "set": rset}
            for metric, v in m.items():
                row.update({f"{metric}_{k}": x for k, x in v.items()})
            rows.append(row)
    return rows


def closedloop_markdown(metrics: dict[str, dict[str, Any]],
                        reference: str = REFERENCE_AGENT) -> str:
    body = []
    for agent, sets in metrics.items():
        for rset, m in sets.items():
            p = m["paired"] or {}
            body.append([
                agent, rset, m["n"], success_text(m["success"], m["n"]),
                failures_text(m["first_failure"]),
                ci_text(m["handover_time"], 2), ci_text(p.get("success"), 2, "diff"),
                ci_text(p.get("handover_time"), 2, "diff"),
            ])
    return (
        "## Closed-loop track\n\n"
        + markdown_table(
            ["agent", "set", "n", "success [95 % Wilson CI]", "first failure",
             "handover time (s) [95 % CI]", f"success − {reference}",
             f"handover time − {reference} (s)"],
            body,
        )
        + "\nFirst failure: each failed episode counted once, at the first check it fails "
        "(docs/benchmark.md). Handover time: median over the successes, bootstrap CI. Paired: "
        f"agent − {reference} on the same receivers, [95 % bootstrap CI over receivers], "
        "* the CI excludes 0.\n"
    )


def openloop_markdown(metrics: dict[str, dict[str, Any]]) -> str:
    header = ["agent", "set", "episodes", *OPENLOOP_METRICS.values()]
    body = []
    for agent, sets in metrics.items():
        for rset, m in sets.items():
            n = next(iter(m.values()))["n"]
            body.append([agent, rset, n, *(ci_text(m[k], 1) for k in OPENLOOP_METRICS)])
    return (
        "## Open-loop track (mm)\n\n"
        + markdown_table(header, body)
        + "\nMean over the test episodes [95 % bootstrap CI of the mean]; the fold means and "
        "standard deviations (Table I's reading) are in openloop_table.csv.\n"
    )
