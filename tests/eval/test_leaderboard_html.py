"""``evaluate.py leaderboard --html``: the page, parsed with the standard library's HTML parser,
agrees with every result.json it was made from (rank, agent, success, handover time, open-loop
errors, per-set rows and first-failure counts, protocol version, fingerprints) and with the
Markdown table; it references nothing outside itself, and strings from result files are
escaped."""

from __future__ import annotations

import base64
import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import pytest

from handover_eval.benchmark.files import read_result
from handover_eval.benchmark.leaderboard import leaderboard_markdown, load_results, rank_key
from handover_eval.benchmark.outcomes import CHECKS
from handover_eval.benchmark.protocol import CLOSEDLOOP_SETS, OPENLOOP_METRICS, TRACKS
from handover_eval.cli import evaluate

URL_RE = re.compile(r"^\s*(https?:)?//", re.IGNORECASE)


class Page(HTMLParser):
    """Every tag with its attributes, every table (by id) as body rows of (text, data-sort) and
    its column names (the last header row)."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.tables: dict[str, list[list[tuple[str, str | None]]]] = {}
        self.headers: dict[str, list[str]] = {}
        self.script_text: list[str] = []
        self._table: str | None = None
        self._cell: list[str] | None = None
        self._sort: str | None = None
        self._in_script = False
        self._in_head = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        self.tags.append((tag, a))
        if tag == "table":
            self._table = a.get("id") or f"table-{len(self.tables)}"
            self.tables[self._table], self.headers[self._table] = [], []
        elif tag == "thead":
            self._in_head = True
        elif tag == "tr" and self._table is not None and self._in_head:
            self.headers[self._table] = []  # the last header row names the columns
        elif tag == "tr" and self._table is not None:
            self.tables[self._table].append([])
        elif tag in ("td", "th"):
            self._cell, self._sort = [], a.get("data-sort")
        elif tag == "script":
            self._in_script = True

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None and self._table is not None:
            text = " ".join("".join(self._cell).split())
            if tag == "th":
                self.headers[self._table].append(text)
            else:
                self.tables[self._table][-1].append((text, self._sort))
            self._cell = None
        elif tag == "thead":
            self._in_head = False
        elif tag == "table" and self._table is not None:
            self.tables[self._table] = [row for row in self.tables[self._table] if row]
            self._table = None
        elif tag == "script":
            self._in_script = False

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)
        if self._in_script:
            self.script_text.append(data)


def _run(args: list[str]) -> None:
    assert evaluate.main(args) == 0


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """Two --quick results of one fingerprint: cv on the open loop, reactive on the closed loop
    (so the page has both tracks, a closed-loop and an open-loop-only rank), and the page."""
    tmp = tmp_path_factory.mktemp("html")
    common = ["--quick", "--no-progress", "--workers", "1", "--checkpoints", str(tmp / "ckpt")]
    _run(["benchmark", "--agent", "cv", "--tracks", "openloop", *common, "--out", str(tmp / "cv")])
    _run(["benchmark", "--agent", "reactive", "--tracks", "closedloop", *common,
          "--out", str(tmp / "reactive")])
    files = [str(tmp / a / "result.json") for a in ("cv", "reactive")]
    _run(["leaderboard", *files, "--html", "--out", str(tmp / "lb")])
    return {"tmp": tmp, "cv": tmp / "cv", "reactive": tmp / "reactive", "lb": tmp / "lb"}


def _parse(path: Path) -> Page:
    page = Page()
    page.feed(path.read_text(encoding="utf-8"))
    page.close()
    return page


def _markdown_rows(md: str) -> list[list[str]]:
    lines = [ln for ln in md.splitlines() if ln.startswith("| ") and not ln.startswith("| ---")]
    return [[c.strip() for c in ln.strip("|").split(" | ")] for ln in lines[1:]]


def test_the_page_agrees_with_the_result_files(runs) -> None:
    results = [read_result(runs[a] / "result.json") for a in ("cv", "reactive")]
    order = sorted(results, key=rank_key)
    page = _parse(runs["lb"] / "leaderboard.html")
    ranking = page.tables["ranking"]
    assert len(ranking) == 2
    for rank, (row, r) in enumerate(zip(ranking, order, strict=True), start=1):
        assert row[0] == (str(rank), str(rank))
        assert row[1] == (r["agent"]["name"] + " (quick)", r["agent"]["name"])
        cl, ol = r["metrics"].get("closedloop"), r["metrics"].get("openloop")
        for k, s in enumerate(("all", *CLOSEDLOOP_SETS), start=2):
            want = cl[s]["success"]["value"] if cl else None
            assert row[k][1] == ("" if want is None else repr(float(want)))
            if want is not None:
                lo, hi = cl[s]["success"]["low"], cl[s]["success"]["high"]
                assert row[k][0] == f"{100 * want:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]"
            else:
                assert row[k][0] == "–"
        want = cl["all"]["handover_time"]["value"] if cl else None
        assert row[8][1] == ("" if want is None else repr(float(want)))
        for k, m in zip((10, 11, 12), ("rms_now_axis_mm", "ade_10_mm", "fde_10_mm"),
                        strict=True):
            want = ol["all"][m]["value"] if ol else None
            assert row[k][1] == ("" if want is None else repr(float(want)))
    # the same cells as the Markdown table, row by row
    md = _markdown_rows(leaderboard_markdown(load_results(
        [str(runs[a] / "result.json") for a in ("cv", "reactive")])))
    assert [[text for text, _ in row] for row in ranking] == md
    # each agent's per-set rows and first-failure counts
    for rank, r in enumerate(order, start=1):
        if "closedloop" in r["tracks"]:
            rows = page.tables[f"closed-{rank}"]
            header = page.headers[f"closed-{rank}"]
            by_set = {row[0][0]: row for row in rows}
            assert set(by_set) == {*CLOSEDLOOP_SETS, "all"}
            for s, m in r["metrics"]["closedloop"].items():
                row = by_set[s]
                assert row[1][0] == str(m["n"]) and row[3][0] == str(m["success"]["k"])
                for c in CHECKS:
                    assert row[header.index(c)][0] == str(
                        m["first_failure"][c])
        if "openloop" in r["tracks"]:
            rows = page.tables[f"open-{rank}"]
            by_set = {row[0][0]: row for row in rows}
            for s, m in r["metrics"]["openloop"].items():
                values = [float(v) for _, v in by_set[s][2:]]
                assert values == [m[k]["value"] for k in OPENLOOP_METRICS]
    # protocol version and every track's fingerprint
    text = (runs["lb"] / "leaderboard.html").read_text(encoding="utf-8")
    assert f"benchmark protocol v{results[0]['protocol_version']}" in text
    prints = {row[0][0]: row for row in page.tables["fingerprints"]}
    assert set(prints) == set(TRACKS)
    for r in results:
        for t in r["tracks"]:
            fp = r["fingerprints"][t]
            assert prints[t][1][0] == fp["fingerprint"] and prints[t][3][0] == fp["data"]
            assert prints[t][2][0] == str(fp["protocol_version"])


def test_the_page_loads_nothing_from_outside(runs) -> None:
    page = _parse(runs["lb"] / "leaderboard.html")
    text = (runs["lb"] / "leaderboard.html").read_text(encoding="utf-8")
    assert "http://" not in text and "https://" not in text
    for tag, attrs in page.tags:
        for name in ("src", "href", "srcset", "action", "data", "poster"):
            value = attrs.get(name)
            if value is None:
                continue
            assert not URL_RE.match(value), (tag, name, value[:80])
            assert value.startswith(("data:image/png;base64,", "#")), (tag, name, value[:80])
        assert not (tag == "link" or (tag == "script" and "src" in attrs)), (tag, attrs)
    csp = [a["content"] for t, a in page.tags
           if t == "meta" and a.get("http-equiv") == "Content-Security-Policy"]
    assert csp and "default-src 'none'" in csp[0]
    # the figure is the PNG the command wrote beside the page
    images = [a["src"] for t, a in page.tags if t == "img"]
    assert len(images) == 1
    png = base64.b64decode(images[0].split(",", 1)[1])
    assert png == (runs["lb"] / "leaderboard.png").read_bytes()
    # the sorting script is inline and the ranked table is sortable
    assert len([t for t, _ in page.tags if t == "script"]) == 1
    assert "sortable" in "".join(page.script_text)
    assert ("table", {"id": "ranking", "class": "sortable"}) in page.tags


def test_strings_from_result_files_are_escaped(runs, tmp_path) -> None:
    data = json.loads((runs["reactive"] / "result.json").read_text())
    data["agent"]["spec"] = '"><script>alert(1)</script>'
    data["agent"]["config"] = {"<img src=x onerror=alert(2)>": "</pre><b>bold</b>"}
    data["software"]["handover_env"] = "<i>9</i>"
    bad = tmp_path / "result.json"
    bad.write_text(json.dumps(data))
    for entry in data["episodes"].values():  # the episode files the result was computed from
        shutil.copy(runs["reactive"] / entry["file"], tmp_path / entry["file"])
    _run(["leaderboard", str(runs["cv"] / "result.json"), str(bad), "--html",
          "--out", str(tmp_path / "lb")])
    text = (tmp_path / "lb" / "leaderboard.html").read_text(encoding="utf-8")
    page = _parse(tmp_path / "lb" / "leaderboard.html")
    assert [t for t, _ in page.tags].count("script") == 1
    assert not any(t in ("b", "i") or (t == "img" and a.get("src") == "x") for t, a in page.tags)
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text and "&lt;i&gt;9&lt;/i&gt;" in text


def test_without_html_no_page_is_written(runs, tmp_path) -> None:
    _run(["leaderboard", str(runs["reactive"] / "result.json"), "--out", str(tmp_path / "lb")])
    assert sorted(p.name for p in (tmp_path / "lb").iterdir() if not p.name.startswith(".")) == [
        "leaderboard.md", "leaderboard.png"]
