"""The documentation points at things that exist: every test it cites, every file it names, every link.

README.md stays an introduction of at most 150 lines; the documents of docs/ exist.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCUMENTS = ("user-guide.md", "method.md", "validation.md", "benchmarks.md", "udp-protocol.md")
PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md"] + sorted((ROOT / "docs").glob("*.md"))
TEST_ID = re.compile(r"(tests/[\w/]+\.py)::(\w+)")
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
REPO_PATH = re.compile(r"`((?:models|fmus|builder|orchestrator|tests|docs)/[\w./-]+\.(?:py|toml|json|md|csv))`")


def _ids(page: Path) -> str:
    return str(page.relative_to(ROOT))


def _test_names(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {n.name for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
            and n.name.startswith("test")}


def test_readme_is_at_most_150_lines():
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 150


def test_the_documents_exist():
    missing = [name for name in DOCUMENTS if not (ROOT / "docs" / name).is_file()]
    assert not missing


@pytest.mark.parametrize("page", PAGES, ids=_ids)
def test_every_cited_test_exists(page: Path):
    cited = TEST_ID.findall(page.read_text(encoding="utf-8"))
    missing = [f"{f}::{name}" for f, name in cited
               if not (ROOT / f).is_file() or name not in _test_names(ROOT / f)]
    assert not missing, f"{_ids(page)} cites tests that do not exist: {missing}"


@pytest.mark.parametrize("page", PAGES, ids=_ids)
def test_every_named_file_exists(page: Path):
    named = REPO_PATH.findall(page.read_text(encoding="utf-8"))
    missing = sorted({p for p in named if not (ROOT / p).exists()})
    assert not missing, f"{_ids(page)} names files that do not exist: {missing}"


@pytest.mark.parametrize("page", PAGES, ids=_ids)
def test_every_relative_link_resolves(page: Path):
    links = [t for t in LINK.findall(page.read_text(encoding="utf-8")) if "://" not in t]
    missing = [t for t in links if not (page.parent / t).exists()]
    assert not missing, f"{_ids(page)} links to files that do not exist: {missing}"
