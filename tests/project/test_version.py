"""One version string: ``handover_env.__version__`` is what pyproject.toml's build reads, what the
installed metadata says, what every result.json records (a --quick benchmark run), and what
CHANGELOG.md and CITATION.cff name; CITATION.cff holds the fields CFF 1.2.0 requires."""

from __future__ import annotations

import datetime
import importlib.metadata
import re
from pathlib import Path

import pytest
from packaging.version import Version
from setuptools.config.pyprojecttoml import read_configuration

from handover_env import __version__
from handover_eval.benchmark.files import read_result
from handover_eval.cli import evaluate

ROOT = Path(__file__).resolve().parents[2]


def test_pyproject_reads_the_package_version() -> None:
    raw = read_configuration(ROOT / "pyproject.toml", expand=False)
    assert "version" not in raw["project"] and "version" in raw["project"]["dynamic"]
    assert raw["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "handover_env.__version__"}
    expanded = read_configuration(ROOT / "pyproject.toml", expand=True)
    assert expanded["project"]["version"] == __version__


def test_the_version_is_pep_440_and_the_installed_metadata_agrees() -> None:
    assert str(Version(__version__)) == __version__
    installed = importlib.metadata.version("handover_env")
    assert installed == __version__, (
        f"installed metadata says {installed}, the code {__version__}: reinstall the package "
        "(make install) so its metadata is rebuilt from handover_env.__version__"
    )


def test_a_result_file_records_the_package_version(tmp_path) -> None:
    assert evaluate.main(["benchmark", "--agent", "cv", "--tracks", "openloop", "--quick",
                          "--no-progress", "--workers", "1", "--checkpoints",
                          str(tmp_path / "ckpt"), "--out", str(tmp_path / "cv")]) == 0
    result = read_result(tmp_path / "cv" / "result.json")
    assert result["software"]["handover_env"] == __version__


def test_the_changelog_has_a_section_for_the_version() -> None:
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    sections = re.findall(r"^## \[([^\]]+)\](?: - (\d{4}-\d{2}-\d{2}))?$", text, re.MULTILINE)
    assert sections[0] == ("Unreleased", "")
    versions = [v for v, _ in sections[1:]]
    assert versions[0] == __version__
    for v, date in sections[1:]:
        assert str(Version(v)) == v and datetime.date.fromisoformat(date)
    assert versions == sorted(versions, key=Version, reverse=True)


def test_citation_cff_names_the_version_and_the_paper() -> None:
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    # CFF 1.2.0: required keys, and only keys the schema knows
    assert {"cff-version", "message", "title", "authors"} <= set(cff)
    assert set(cff) <= {"abstract", "authors", "cff-version", "commit", "contact",
                        "date-released", "doi", "identifiers", "keywords", "license",
                        "license-url", "message", "preferred-citation", "references",
                        "repository", "repository-artifact", "repository-code", "title", "type",
                        "url", "version"}
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert cff["version"] == __version__
    assert cff["license"] == read_configuration(ROOT / "pyproject.toml")["project"]["license"]
    paper = cff["preferred-citation"]
    assert {"authors", "title", "type"} <= set(paper) and paper["type"] == "conference-paper"
    assert paper["title"] == "Learning-based Dynamic Robot-to-Human Handover"
    assert [a["family-names"] for a in paper["authors"]] == ["Kim", "Kim", "Pan", "Lee", "Choi"]
    assert all(set(a) == {"family-names", "given-names"} for a in paper["authors"])
    assert isinstance(paper["year"], int) and paper["year"] == 2025
    assert re.match(r"^(https|http|ftp|sftp)://.+", paper["url"])
    for who in cff["authors"]:
        assert "name" in who or "family-names" in who or "given-names" in who
