"""The demo's values turned into what is shown: the side-by-side frames, the summary and its text.

The summary answers the paper's H2 (Sec. V-C) on the demo's walkers: for each side, how many
handovers succeeded and the median handover time of the successes (``info["handover_time"]``:
from the walker's departure to the release, the static baseline's 2 s stabilisation delay
subtracted as the paper does; with it, ``handover_time_with_delay``), and every outcome and first
failure under the benchmark's names (:mod:`handover_eval.benchmark.outcomes`). Nothing here
writes a file (:mod:`.output` does).
"""

from __future__ import annotations

import statistics
from collections import Counter
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from handover_env.config import HandoverParams
from handover_eval.benchmark.outcomes import CHECKS
from handover_eval.demo.caption import STYLE, CaptionStyle, caption_lines, panel, title_bar
from handover_eval.demo.run import SIDES, DemoEpisode, DemoRun, handover_times
from handover_eval.reporting import markdown_table

#: Frames the last picture is held at the end of the video (1 s at 15 fps).
HOLD_FRAMES = 15
#: The paper's user study (Sec. V-C): handover time, mean and SD over 8 people x 5 trials, s.
PAPER_HANDOVER_TIME = {"dynamic": (3.2, 0.50), "static": (6.9, 1.2)}
_LABELS = {s.key: s.agent_label for s in SIDES}


def _median(values: Sequence[float]) -> float:
    return float(statistics.median(values)) if values else float("nan")


def summary(run: DemoRun) -> list[dict[str, Any]]:
    """One row per side: ``side``, ``agent``, ``episodes``, ``successes``, ``success_rate``,
    ``median_handover_time_s`` and ``median_handover_time_with_delay_s`` (over the successes;
    NaN without one), ``outcomes`` and ``first_failures`` (``name count`` pairs, most common
    first, the benchmark's names)."""
    rows = []
    for side in SIDES:
        eps = run.episodes[side.key]
        n_ok = sum(1 for e in eps if e.row["success"])
        outcomes = Counter(str(e.row["outcome"]) for e in eps)
        failures = Counter(str(e.row["first_failure"]) for e in eps if not e.row["success"])
        rows.append({
            "side": side.key,
            "agent": side.agent_label,
            "episodes": len(eps),
            "successes": n_ok,
            "success_rate": n_ok / len(eps) if eps else float("nan"),
            "median_handover_time_s": _median(handover_times(eps)),
            "median_handover_time_with_delay_s": _median(
                handover_times(eps, "handover_time_with_delay")),
            "outcomes": _counts(outcomes),
            "first_failures": _counts(failures, order=CHECKS),
        })
    return rows


def _counts(counter: Counter, order: Sequence[str] = ()) -> str:
    keys = sorted(counter, key=lambda k: (order.index(k) if k in order else len(order),
                                          -counter[k], k))
    return ", ".join(f"{k} {counter[k]}" for k in keys) or "-"


def episode_rows(run: DemoRun) -> list[dict[str, Any]]:
    """Every episode's benchmark row, side by side key order then seed order."""
    return [dict(e.row) for side in SIDES for e in run.episodes[side.key]]


def _seconds(v: float) -> str:
    return "-" if v != v else f"{v:.2f}"


def summary_markdown(run: DemoRun) -> str:
    """The summary table, the per-walker table and the paper's figures, as Markdown."""
    rows = summary(run)
    seeds = [e.seed for e in run.episodes[SIDES[0].key]]
    head = ["side", "success", "median handover time (s)", "with the 2 s delay (s)",
            "outcomes", "first failures", "paper (mean ± SD, s)"]
    body = [[r["agent"], f"{r['successes']}/{r['episodes']}",
             _seconds(r["median_handover_time_s"]),
             _seconds(r["median_handover_time_with_delay_s"]), r["outcomes"],
             r["first_failures"], "{:.1f} ± {:.2g}".format(*PAPER_HANDOVER_TIME[r["side"]])]
            for r in rows]
    by_seed = {s.key: {e.seed: e.row for e in run.episodes[s.key]} for s in SIDES}
    per = [[str(seed)] + [_cell(by_seed[s.key][seed]) for s in SIDES] for seed in seeds]
    return "\n".join([
        "# Dynamic vs static handover on the same seeded walkers",
        "",
        f"{len(seeds)} scripted ID walkers (seeds {', '.join(map(str, seeds))}, fixed before "
        "their episodes were run) met the SPGP planner in `DynamicHandover-v0` and the static "
        "baseline in `StaticHandover-v0`, both at Θ-hat, on the embedded synthetic default. "
        "Handover time: from the walker's departure to the release, the static baseline's 2 s "
        "stabilisation delay subtracted (paper Sec. V-C); medians over the successes. Outcomes "
        "and first failures use the benchmark's names.",
        "",
        markdown_table(head, body).rstrip("\n"),
        "",
        "The paper's figures are its user study's (8 people, 5 trials each, the real UR5e); "
        "these are simulated walkers.",
        "",
        markdown_table(["seed", *(_LABELS[s.key] for s in SIDES)], per).rstrip("\n"),
        "",
    ])


def _cell(row: dict[str, Any]) -> str:
    if row["success"]:
        return f"success, {float(row['handover_time']):.2f} s"
    return f"{row['outcome']} (first failure: {row['first_failure']})"


def summary_lines(run: DemoRun) -> list[str]:
    """The printed summary: one line per side."""
    return [
        f"{r['agent']:40s} success {r['successes']}/{r['episodes']}  median handover time "
        f"{_seconds(r['median_handover_time_s'])} s (with the 2 s delay "
        f"{_seconds(r['median_handover_time_with_delay_s'])} s)  outcomes: {r['outcomes']}"
        f"  first failures: {r['first_failures']}"
        for r in summary(run)
    ]


def episode_line(e: DemoEpisode) -> str:
    """One printed line per episode, as it finishes."""
    r = e.row
    ho = "-" if not r["success"] else f"{float(r['handover_time']):.2f} s"
    ff = f" (first failure: {r['first_failure']})" if r["first_failure"] else ""
    return (f"{e.side:8s} walker {e.seed}: {r['outcome']}{ff}, handover time {ho}, "
            f"peak wrist force {float(r['peak_wrist_force']):.1f} N, body contact "
            f"{float(r['body_contact_force']):.1f} N ({e.wall:.1f} s wall)")


def side_by_side(dynamic: DemoEpisode, static: DemoEpisode,
                 style: CaptionStyle = STYLE) -> Iterator[np.ndarray]:
    """The video's frames: left the dynamic side, right the static side, at the same simulated
    times (a side that has ended holds its last picture, with its outcome), under a title bar;
    the last frame is held :data:`HOLD_FRAMES` more times."""
    if not dynamic.frames or not static.frames:
        raise ValueError("both episodes must have been filmed")
    if dynamic.seed != static.seed:
        raise ValueError(f"the two sides met different walkers: {dynamic.seed} vs {static.seed}")
    f_r = HandoverParams().release_force
    n = max(len(dynamic.frames), len(static.frames))
    width = dynamic.frames[0].shape[1] + static.frames[0].shape[1]
    title = title_bar(f"The same walker (ID, seed {dynamic.seed})   left: dynamic handover   "
                      "right: static handover", width, style)
    frame = title
    drawn: dict[str, tuple[int, np.ndarray]] = {}  # a side that has ended keeps its panel
    for k in range(n):
        sides = []
        for e in (dynamic, static):
            j = min(k, len(e.frames) - 1)
            if drawn.get(e.side, (-1,))[0] != j:
                done = e.row if j == len(e.frames) - 1 else None
                lines = caption_lines(_LABELS[e.side], e.moments[j], done, f_r)
                drawn[e.side] = (j, panel(e.frames[j], lines, style))
            sides.append(drawn[e.side][1])
        frame = np.concatenate([title, np.concatenate(sides, axis=1)], axis=0)
        yield frame
    for _ in range(HOLD_FRAMES):
        yield frame


def still_index(dynamic: DemoEpisode) -> int:
    """The frame of the still: the dynamic side's release (its first filmed frame after it), or
    its last frame when it never released."""
    for k, m in enumerate(dynamic.moments):
        if m.release_time is not None:
            return k
    return len(dynamic.frames) - 1
