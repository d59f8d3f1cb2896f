"""``evaluate.py leaderboard --html``: the leaderboard as one self-contained HTML page.

The page needs no network when it is viewed: the style and the column-sorting script are inline,
the leaderboard figure is embedded as a ``data:image/png;base64`` URI, every other link is a
fragment (``#agent-1``) within the page, and a Content-Security-Policy ``<meta>`` tells the
browser to load nothing from anywhere else (``default-src 'none'``). It holds:

* the ranked table of :func:`.leaderboard.leaderboard_markdown` (same order from
  :func:`.leaderboard.rank_key`, same cells), sortable by any column;
* the leaderboard figure (:func:`.leaderboard.leaderboard_figure`, as written to
  ``leaderboard.png``);
* per agent: what was scored (kind, spec, plug-in SHA-256, config, software, timing), the
  closed-loop rows of every receiver set with their first-failure counts, and the open-loop rows;
* the protocol version and each track's fingerprint with its parts.

Every string taken from a result file (agent names, specs, configs, versions, file names) is
passed through :func:`html.escape`; result files are untrusted input. Numbers are formatted here.
Sortable cells carry their exact value in ``data-sort`` (``repr`` of the float, empty when there
is none; empty cells sort last in either direction).
"""

from __future__ import annotations

import base64
import json
from collections.abc import Iterable, Sequence
from html import escape
from typing import Any

from handover_eval.benchmark.leaderboard import ci_cell, rank_key
from handover_eval.benchmark.outcomes import CHECKS
from handover_eval.benchmark.protocol import (
    CLOSEDLOOP_SETS,
    OPENLOOP_METRICS,
    OPENLOOP_SETS,
    REFERENCE_AGENT,
    TRACKS,
)

NONE = "–"
#: What the page allows the browser to load: nothing but its own inline style, script and
#: data: images.
CSP = ("default-src 'none'; img-src data:; style-src 'unsafe-inline'; "
       "script-src 'unsafe-inline'; base-uri 'none'; form-action 'none'")
STYLE = """
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; margin: 1.5em auto;
       max-width: 1500px; padding: 0 1em; color: #1b1f24; }
div.scroll { overflow-x: auto; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h1 small { color: #57606a; font-weight: normal; }
h2 { border-bottom: 1px solid #d0d7de; padding-bottom: 0.2em; margin-top: 1.8em; }
table { border-collapse: collapse; margin: 0.6em 0; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #d0d7de; padding: 0.25em 0.55em; text-align: right; }
td { white-space: nowrap; }
th { background: #f6f8fa; vertical-align: bottom; }
th.group { text-align: center; font-weight: normal; color: #57606a; }
td.text, th.text { text-align: left; }
table.sortable th:not(.group) { cursor: pointer; user-select: none; }
table.sortable th:not(.group)::after { content: " \\2195"; color: #8c959f; }
table.sortable th[aria-sort=ascending]::after { content: " \\2191"; color: #1b1f24; }
table.sortable th[aria-sort=descending]::after { content: " \\2193"; color: #1b1f24; }
tbody tr:nth-child(even) { background: #f6f8fa; }
.note { color: #57606a; max-width: 110ch; }
.warn { background: #fff8c5; border: 1px solid #d4a72c; padding: 0.4em 0.7em; }
figure { margin: 1em 0; } figure img { max-width: 100%; height: auto; }
code, pre { font: 12px/1.4 ui-monospace, SFMono-Regular, Menlo, monospace; }
pre { background: #f6f8fa; padding: 0.6em; overflow-x: auto; max-width: 100%; }
dl { display: grid; grid-template-columns: max-content auto; gap: 0.1em 1em; }
dt { color: #57606a; } dd { margin: 0; word-break: break-all; }
section.agent { margin-top: 1.4em; }
small.sub, span.ci { display: block; color: #57606a; font-size: 0.85em; }
"""
#: Sorts a ``table.sortable`` by the clicked column: numbers as numbers, text as text, cells
#: without a value last.
SCRIPT = """
document.querySelectorAll("table.sortable").forEach(function (table) {
  var heads = table.tHead.rows[table.tHead.rows.length - 1].cells;
  Array.prototype.forEach.call(heads, function (th, col) {
    th.tabIndex = 0;
    function sort() {
      var asc = th.getAttribute("aria-sort") !== "ascending";
      Array.prototype.forEach.call(heads, function (h) { h.removeAttribute("aria-sort"); });
      th.setAttribute("aria-sort", asc ? "ascending" : "descending");
      var body = table.tBodies[0], rows = Array.prototype.slice.call(body.rows);
      function key(row) {
        var cell = row.cells[col], v = cell.getAttribute("data-sort");
        return v === null ? cell.textContent.trim() : v;
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        if (x === "" || y === "") { return (x === "") - (y === ""); }
        var nx = Number(x), ny = Number(y), d;
        d = (isNaN(nx) || isNaN(ny)) ? x.localeCompare(y) : nx - ny;
        return asc ? d : -d;
      });
      rows.forEach(function (row) { body.appendChild(row); });
    }
    th.addEventListener("click", sort);
    th.addEventListener("keydown", function (e) { if (e.key === "Enter") { sort(); } });
  });
});
"""


def _get(d: Any, *keys: str) -> Any:
    for k in keys:
        if not isinstance(d, dict) or d.get(k) is None:
            return None
        d = d[k]
    return d


def _num(v: Any) -> str:
    """The exact value for ``data-sort`` ("" for none)."""
    return repr(float(v)) if isinstance(v, (int, float)) and not isinstance(v, bool) else ""


def pct(c: dict | None) -> str:
    """'83 % [76, 88]': a success share with its Wilson CI (the Markdown table's cell)."""
    if c is None or c.get("value") is None:
        return NONE
    return f"{100 * c['value']:.0f} % [{100 * c['low']:.0f}, {100 * c['high']:.0f}]"


def _td(text: str, sort: str | None = None, cls: str = "", inner: str | None = None) -> str:
    """One cell: ``text`` escaped (or ``inner``, already HTML), ``sort`` its data-sort value."""
    attrs = (f' class="{cls}"' if cls else "") + (
        f' data-sort="{escape(sort)}"' if sort is not None else "")
    return f"<td{attrs}>{escape(text) if inner is None else inner}</td>"


def _with_ci(text: str) -> str:
    """A value cell's HTML: the value, then its CI on its own line (the text is unchanged)."""
    value, sep, rest = text.partition(" [")
    if not sep:
        return escape(text)
    return f'{escape(value)} <span class="ci">[{escape(rest)}</span>'


def _td_ci(text: str, sort: str, inner_extra: str = "") -> str:
    """A cell of a value and its CI (:func:`pct`, :func:`ci`), sorted by the value."""
    return _td(text, sort, inner=_with_ci(text) + inner_extra)


def _table(header: Sequence[str], rows: Iterable[str], table_id: str,
           sortable: bool = True, text: Sequence[int] = (0,),
           groups: Sequence[tuple[str, int]] = ()) -> str:
    """A table of already-built ``<tr>`` rows; the headers of columns ``text`` left-aligned.

    ``groups``: an optional first header row of (label, columns spanned); sorting uses the
    last header row."""
    ths = "".join(f'<th class="text">{escape(h)}</th>' if i in text else f"<th>{escape(h)}</th>"
                  for i, h in enumerate(header))
    top = ("<tr>" + "".join(f'<th class="group" colspan="{n}">{escape(label)}</th>'
                            for label, n in groups) + "</tr>") if groups else ""
    attrs = f' id="{table_id}"' + (' class="sortable"' if sortable else "")
    return (f'<div class="scroll"><table{attrs}><thead>{top}<tr>{ths}</tr></thead><tbody>\n'
            + "\n".join(rows) + "\n</tbody></table></div>\n")


def ranked(results: Sequence[tuple[str, dict]]) -> list[tuple[str, dict]]:
    """The results in leaderboard order (:func:`.leaderboard.rank_key`)."""
    return sorted(results, key=lambda fd: rank_key(fd[1]))


RANK_HEADER = ["rank", "agent", "success, all", *(f"success, {s}" for s in CLOSEDLOOP_SETS),
               "handover time (s)", f"far-pass success − {REFERENCE_AGENT}",
               "current-frame RMS (mm)", "ADE 1 s (mm)", "FDE 1 s (mm)"]


def _ranking(results: Sequence[tuple[str, dict]]) -> str:
    rows = []
    for i, (_, r) in enumerate(ranked(results), start=1):
        cl = _get(r, "metrics", "closedloop") or {}
        ol = _get(r, "metrics", "openloop") or {}
        name = r["agent"]["name"] + (" (quick)" if r["quick"] else "")
        cells = [_td(str(i), str(i)),
                 _td(name, r["agent"]["name"], "text",
                     f'<a href="#agent-{i}">{escape(name)}</a>')]
        for s in ("all", *CLOSEDLOOP_SETS):
            c = _get(cl, s, "success")
            cells.append(_td_ci(pct(c), _num(_get(c, "value"))))
        c = _get(cl, "all", "handover_time")
        cells.append(_td_ci(ci_cell(c, 2), _num(_get(c, "value"))))
        c = _get(cl, "far-pass", "paired", "success")
        cells.append(_td_ci(ci_cell(c, 2, "diff"), _num(_get(c, "diff"))))
        for m in ("rms_now_axis_mm", "ade_10_mm", "fde_10_mm"):
            c = _get(ol, "all", m)
            cells.append(_td_ci(ci_cell(c, 1), _num(_get(c, "value"))))
        rows.append(f'<tr id="rank-{i}">' + "".join(cells) + "</tr>")
    return _table(RANK_HEADER, rows, "ranking", text=(1,))


CLOSED_HEADER = ["set", "episodes", "success", "successes", "handover time (s)",
                 f"success − {REFERENCE_AGENT}", f"handover time − {REFERENCE_AGENT} (s)",
                 *CHECKS]
#: The closed-loop table's header groups: the episode columns, then the first-failure counts.
CLOSED_GROUPS = [("", len(CLOSED_HEADER) - len(CHECKS)),
                 ("episodes by first failed check (docs/benchmark.md)", len(CHECKS))]


def _closed_rows(cl: dict, rank: int) -> str:
    rows = []
    for s in (*CLOSEDLOOP_SETS, "all"):
        m = cl.get(s)
        if not isinstance(m, dict):
            continue
        succ, ht = m.get("success"), m.get("handover_time")
        ps, pt = _get(m, "paired", "success"), _get(m, "paired", "handover_time")
        cells = [_td(s, s, "text"), _td(str(m["n"]), _num(m["n"])),
                 _td_ci(pct(succ), _num(_get(succ, "value"))),
                 _td(str(_get(succ, "k")), _num(_get(succ, "k"))),
                 _td_ci(ci_cell(ht, 2), _num(_get(ht, "value"))),
                 _td_ci(ci_cell(ps, 2, "diff"), _num(_get(ps, "diff"))),
                 _td_ci(ci_cell(pt, 2, "diff"), _num(_get(pt, "diff")))]
        ff = m.get("first_failure") or {}
        cells += [_td(str(ff.get(c, NONE)), _num(ff.get(c))) for c in CHECKS]
        rows.append(f'<tr data-set="{escape(s)}">' + "".join(cells) + "</tr>")
    return _table(CLOSED_HEADER, rows, f"closed-{rank}", groups=CLOSED_GROUPS)


def _open_rows(ol: dict, rank: int) -> str:
    rows = []
    for s in (*OPENLOOP_SETS, "all"):
        m = ol.get(s)
        if not isinstance(m, dict):
            continue
        n = _get(m, "rms_now_axis_mm", "n")
        cells = [_td(s, s, "text"), _td(str(n), _num(n))]
        for key in OPENLOOP_METRICS:
            c = m.get(key)
            folds = (f"folds {c['fold_mean']:.1f} ± {c['fold_std']:.1f}"
                     if c and c.get("fold_mean") is not None and c.get("fold_std") is not None
                     else "")
            cells.append(_td_ci(ci_cell(c, 1), _num(_get(c, "value")),
                                f' <small class="sub">{escape(folds)}</small>' if folds else ""))
        rows.append(f'<tr data-set="{escape(s)}">' + "".join(cells) + "</tr>")
    return _table(["set", "episodes", *(f"{v} (mm)" for v in OPENLOOP_METRICS.values())], rows,
                  f"open-{rank}")


def _json_block(value: Any) -> str:
    return "<pre>" + escape(json.dumps(value, indent=2, sort_keys=True)) + "</pre>"


def _dl(items: Iterable[tuple[str, str]]) -> str:
    return "<dl>" + "".join(f"<dt>{escape(k)}</dt><dd>{escape(v)}</dd>" for k, v in items) \
        + "</dl>"


def _agent(rank: int, file: str, r: dict) -> str:
    a = r["agent"]
    software = r.get("software") if isinstance(r.get("software"), dict) else {}
    timing = r.get("timing") if isinstance(r.get("timing"), dict) else {}
    parts = [
        f'<section class="agent" id="agent-{rank}"><h3>{rank}. {escape(a["name"])}'
        + (" <small>(quick)</small>" if r["quick"] else "") + "</h3>",
        _dl([("result file", file), ("kind", a["kind"]), ("spec", a["spec"]),
             ("source SHA-256", a["source_sha256"] or NONE),
             ("tracks", ", ".join(r["tracks"])),
             ("software", ", ".join(f"{k} {v}" for k, v in sorted(software.items()))),
             ("timing", ", ".join(f"{k} {v}" for k, v in sorted(timing.items())))]),
        "<details><summary>config</summary>" + _json_block(a["config"]) + "</details>",
    ]
    cl, ol = _get(r, "metrics", "closedloop"), _get(r, "metrics", "openloop")
    if isinstance(cl, dict):
        parts += ["<h4>Closed loop: every receiver set, with first-failure counts</h4>",
                  _closed_rows(cl, rank)]
    if isinstance(ol, dict):
        parts += ["<h4>Open loop: every test episode, by set</h4>", _open_rows(ol, rank)]
    return "\n".join(parts) + "</section>\n"


FINGERPRINT_HEADER = ["track", "fingerprint", "protocol version", "data", "replay data",
                      "receivers", "receivers (n)"]


def _fingerprints(results: Sequence[tuple[str, dict]]) -> str:
    rows, settings = [], []
    for track in TRACKS:
        fp = next((r["fingerprints"][track] for _, r in results if track in r["tracks"]), None)
        if fp is None:
            continue
        cells = [_td(track, track, "text"), _td(str(fp["fingerprint"]), cls="text"),
                 _td(str(fp["protocol_version"]))]
        cells += [_td(NONE if fp.get(k) is None else str(fp[k]), cls="text")
                  for k in ("data", "replay_data", "receivers")]
        cells.append(_td(NONE if fp.get("n_receivers") is None else str(fp["n_receivers"])))
        rows.append(f'<tr data-track="{escape(track)}">' + "".join(cells) + "</tr>")
        settings.append(f"<details><summary>{escape(track)}: protocol settings</summary>"
                        + _json_block(fp.get("protocol")) + "</details>")
    return (_table(FINGERPRINT_HEADER, rows, "fingerprints", sortable=False, text=(0, 1, 3, 4, 5))
            + "\n".join(settings))


def leaderboard_html(results: Sequence[tuple[str, dict]], figure_png: bytes) -> str:
    """The page (module docstring) of ``results`` (as :func:`.leaderboard.load_results` returns
    them: checked, one protocol version, agreeing fingerprints) and the figure's PNG bytes."""
    if not results:
        raise ValueError("no results to show")
    version = results[0][1]["protocol_version"]
    quick = any(r["quick"] for _, r in results)
    image = base64.b64encode(figure_png).decode("ascii")
    agents = "\n".join(_agent(i, f, r) for i, (f, r) in enumerate(ranked(results), start=1))
    title = f"Leaderboard, benchmark protocol v{int(version)}"
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{CSP}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{escape(title)}</title>
<style>{STYLE}</style>
</head>
<body>
<h1>Leaderboard <small>benchmark protocol v{int(version)}</small></h1>
{'<p class="warn">Quick runs: never for reported numbers.</p>' if quick else ''}
<p class="note">{len(results)} result file(s) of protocol v{int(version)} whose fingerprints
agree track by track (the same data, scoring data and receivers). Ranked by success over all
closed-loop receivers, then far-pass success, then handover time; results with the open-loop
track only follow, by current-frame RMS (docs/benchmark.md). Click a column heading to sort by
it; click an agent for its per-set rows.</p>
<h2 id="ranked">Ranked table</h2>
{_ranking(results)}
<p class="note">Success: share of episodes [95 % Wilson CI]. Handover time: median over
successes [95 % bootstrap CI]. far-pass success − {escape(REFERENCE_AGENT)}: paired on the same
receivers [95 % bootstrap CI], * the CI excludes 0. Open-loop errors: mean over test episodes
[95 % bootstrap CI].</p>
<figure><img alt="{escape(title)}: closed-loop success per receiver set and open-loop errors per
agent" src="data:image/png;base64,{image}"><figcaption class="note">Closed-loop success per
receiver set (95 % Wilson CIs) and the open-loop errors, per agent in rank
order.</figcaption></figure>
<h2 id="agents">Agents</h2>
{agents}
<h2 id="protocol">Protocol v{int(version)} and fingerprints</h2>
<p class="note">Each track's fingerprint hashes the protocol version, the data the agents fit
on, the scoring data and, for the closed loop, every receiver (set, key, seed, far-pass line,
fold). Every result file above has these.</p>
{_fingerprints(results)}
<script>{SCRIPT}</script>
</body>
</html>
"""
