"""``evaluate.py leaderboard``: the ranked Markdown table and a figure from result files.

Only comparable results are ranked together: every file must be of one protocol version,
and for each track every result that reports it must share that track's fingerprint (the same
data, the same scoring data and receivers, the same protocol settings); otherwise
:class:`LeaderboardError` says which files differ and how, in one line. Rank: by closed-loop
success over all test receivers, then far-pass success, then the median handover time; results
with the open-loop track only follow, by current-frame RMS.

A result is ranked only beside the episode files it was computed from: each file its
``episodes`` field names must lie beside it with the SHA-256 recorded there (a run that failed
half-way, or an edited file, is refused). At most :data:`MAX_RESULTS` files are ranked at once,
each checked as soon as it is parsed, so memory stays bounded.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from handover_eval.benchmark.files import (
    BenchmarkFileError,
    check_result,
    load_json,
    protocol_version_of,
    sha256_episode_file,
)
from handover_eval.benchmark.protocol import CLOSEDLOOP_SETS, REFERENCE_AGENT, TRACKS
from handover_eval.closedloop.stats import ci_excludes_zero
from handover_eval.reporting import markdown_table


class LeaderboardError(ValueError):
    """Results that cannot be ranked together (one line: which files, why)."""


MAX_RESULTS = 100


def load_results(paths: Sequence[str | Path]) -> list[tuple[str, dict]]:
    """Every file parsed, its protocol version compared with the first's, every field checked;
    then the fingerprints, the agents and the episode files beside each (module docstring)."""
    if not paths:
        raise LeaderboardError("no result file given")
    if len(paths) > MAX_RESULTS:
        raise LeaderboardError(f"{len(paths)} result files: at most {MAX_RESULTS} are ranked at "
                               "once")
    raw: list[tuple[str, dict]] = []
    for p in paths:
        f, d = str(p), load_json(p)
        v = protocol_version_of(d, f)
        if raw and v != raw[0][1]["protocol_version"]:
            raise LeaderboardError(
                f"{f} is protocol version {v!r} but {raw[0][0]} is "
                f"{raw[0][1]['protocol_version']!r}: results of different protocol versions are "
                "not comparable"
            )
        check_result(d, f)
        raw.append((f, d))
    for track in TRACKS:
        have = [(f, d["fingerprints"][track]) for f, d in raw if track in d["tracks"]]
        for f, fp in have[1:]:
            ref_file, ref = have[0]
            if fp["fingerprint"] != ref["fingerprint"]:
                raise LeaderboardError(
                    f"{f} and {ref_file} differ in the {track} fingerprint "
                    f"({fp['fingerprint'][:8]} vs {ref['fingerprint'][:8]}: "
                    f"{_what_differs(fp, ref)}): not scored on the same data and receivers"
                )
    names = [d["agent"]["name"] for _, d in raw]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise LeaderboardError(f"two results are for agent {dup!r}: rank each agent once")
    for f, d in raw:
        check_episode_files(f, d)
    return raw


def check_episode_files(file: str, result: dict) -> None:
    """The episode files ``result`` (read from ``file``) names lie beside it with the SHA-256 it
    records; else a :class:`LeaderboardError` naming the file and the field."""
    for track, entry in result["episodes"].items():
        path = Path(file).parent / entry["file"]
        if not (path.exists() or path.is_symlink()):
            raise LeaderboardError(
                f"{file}: field episodes.{track}.file: {path} is missing (a result is ranked "
                "only beside the episode files it was computed from)"
            )
        try:
            digest = sha256_episode_file(path)
        except BenchmarkFileError as exc:
            raise LeaderboardError(f"{file}: field episodes.{track}.file: {exc}") from None
        if digest != entry["sha256"]:
            raise LeaderboardError(
                f"{file}: field episodes.{track}.sha256 is {entry['sha256'][:12]}… but {path} "
                f"beside it hashes to {digest[:12]}… (another run's, or edited, files)"
            )


def _what_differs(a: dict, b: dict) -> str:
    keys = [k for k in sorted(set(a) | set(b)) if k != "fingerprint" and a.get(k) != b.get(k)]
    return "different " + ", ".join(keys) if keys else "different contents"


def _get(d: dict, *keys: str) -> Any:
    for k in keys:
        if not isinstance(d, dict) or d.get(k) is None:
            return None
        d = d[k]
    return d


def _finite_or(v: Any, default: float) -> float:
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else default


def rank_key(result: dict) -> tuple:
    """Sort key (module docstring): higher success first, then faster, then lower RMS."""
    cl = _get(result, "metrics", "closedloop")
    if cl is not None:
        return (0, -_finite_or(_get(cl, "all", "success", "value"), -1.0),
                -_finite_or(_get(cl, "far-pass", "success", "value"), -1.0),
                _finite_or(_get(cl, "all", "handover_time", "value"), math.inf),
                result["agent"]["name"])
    ol = _get(result, "metrics", "openloop")
    return (1, _finite_or(_get(ol, "all", "rms_now_axis_mm", "value"), math.inf), 0.0, 0.0,
            result["agent"]["name"])


def _pct(c: dict | None) -> str:
    if c is None or c.get("value") is None:
        return "–"
    return f"{100 * c['value']:.0f} % [{100 * c['low']:.0f}, {100 * c['high']:.0f}]"


def ci_cell(c: dict | None, digits: int, key: str = "value") -> str:
    """'2.31 [2.20, 2.45]', or for a paired difference ('diff') '+0.04 [+0.02, +0.07] *' with
    the star when the CI excludes 0; '–' when there is none (the leaderboard's cell, on the
    Markdown table and the HTML page alike)."""
    if c is None or c.get(key) is None or c.get("low") is None:
        return "–"
    sign = "+" if key == "diff" else ""
    star = " *" if key == "diff" and ci_excludes_zero(c["low"], c["high"]) else ""
    return f"{c[key]:{sign}.{digits}f} [{c['low']:{sign}.{digits}f}, " \
           f"{c['high']:{sign}.{digits}f}]{star}"


def leaderboard_markdown(results: list[tuple[str, dict]]) -> str:
    """The ranked table and what it was scored on."""
    ranked = sorted(results, key=lambda fd: rank_key(fd[1]))
    body = []
    for i, (_, r) in enumerate(ranked, start=1):
        cl = _get(r, "metrics", "closedloop") or {}
        ol = _get(r, "metrics", "openloop") or {}
        body.append([
            i,
            r["agent"]["name"] + (" (quick)" if r["quick"] else ""),
            _pct(_get(cl, "all", "success")),
            *(_pct(_get(cl, s, "success")) for s in CLOSEDLOOP_SETS),
            ci_cell(_get(cl, "all", "handover_time"), 2),
            ci_cell(_get(cl, "far-pass", "paired", "success"), 2, "diff"),
            ci_cell(_get(ol, "all", "rms_now_axis_mm"), 1),
            ci_cell(_get(ol, "all", "ade_10_mm"), 1),
            ci_cell(_get(ol, "all", "fde_10_mm"), 1),
        ])
    header = ["rank", "agent", "success, all", *(f"success, {s}" for s in CLOSEDLOOP_SETS),
              "handover time (s)", f"far-pass success − {REFERENCE_AGENT}",
              "current-frame RMS (mm)", "ADE 1 s (mm)", "FDE 1 s (mm)"]
    first = results[0][1]
    prints = "; ".join(
        f"{t} {first['fingerprints'][t]['fingerprint'][:12]}"
        for t in TRACKS
        if any(t in r["tracks"] for _, r in results) and t in first["fingerprints"]
    )
    quick = any(r["quick"] for _, r in results)
    return (
        f"# Leaderboard (benchmark protocol v{first['protocol_version']})\n\n"
        + markdown_table(header, body)
        + f"\n{len(results)} result file(s); fingerprints {prints or '–'}. Success: share of "
        "episodes [95 % Wilson CI]; handover time: median over successes [95 % bootstrap CI]; "
        f"far-pass success − {REFERENCE_AGENT}: paired on the same receivers [95 % bootstrap "
        "CI], * the CI excludes 0; open-loop errors: mean over test episodes [95 % bootstrap "
        "CI]. Ranked by success over all closed-loop receivers, then far-pass success, then "
        "handover time (docs/benchmark.md)."
        + (" **Quick runs: never for reported numbers.**" if quick else "")
        + "\n"
    )


def leaderboard_figure(results: list[tuple[str, dict]]) -> Any:
    """Closed-loop success per receiver set (Wilson CIs) and the open-loop errors, per agent."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ranked = [r for _, r in sorted(results, key=lambda fd: rank_key(fd[1]))]
    names = [r["agent"]["name"] for r in ranked]
    fig, axes = plt.subplots(1, 2, figsize=(max(10.0, 1.4 * len(names) + 4), 4.2), dpi=130)
    x = np.arange(len(names))
    sets = [*CLOSEDLOOP_SETS, "all"]
    width = 0.8 / len(sets)
    for k, s in enumerate(sets):
        vals, lo, hi = [], [], []
        for r in ranked:
            c = _get(r, "metrics", "closedloop", s, "success")
            v = 100 * c["value"] if c and c["value"] is not None else math.nan
            vals.append(v)
            # max(0, ...): a Wilson bound at a rate of 0 or 1 can miss it by a rounding error
            # (25/25 gives a high of 0.9999999999999999)
            lo.append(max(0.0, v - 100 * c["low"]) if c and c["low"] is not None else 0.0)
            hi.append(max(0.0, 100 * c["high"] - v) if c and c["high"] is not None else 0.0)
        pos = x + (k - (len(sets) - 1) / 2) * width
        axes[0].bar(pos, vals, width, label=s)
        axes[0].errorbar(pos, vals, yerr=[lo, hi], fmt="none", ecolor="k", capsize=2, lw=0.7)
    axes[0].set_ylabel("closed-loop success (%), 95 % Wilson CI")
    axes[0].set_ylim(0, 105)
    axes[0].legend(fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=len(sets),
                   frameon=False)
    metrics = [("rms_now_axis_mm", "current-frame RMS"), ("ade_10_mm", "ADE 1 s"),
               ("fde_10_mm", "FDE 1 s")]
    width = 0.8 / len(metrics)
    for k, (m, label) in enumerate(metrics):
        vals = [(_get(r, "metrics", "openloop", "all", m, "value") or math.nan) for r in ranked]
        axes[1].bar(x + (k - 1) * width, vals, width, label=label)
    axes[1].set_ylabel("open-loop error (mm), all test episodes")
    axes[1].legend(fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3,
                   frameon=False)
    for ax in axes:
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(f"Leaderboard, benchmark protocol v{ranked[0]['protocol_version']}", fontsize=10)
    fig.tight_layout()
    return fig

