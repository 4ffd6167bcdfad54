"""Every public function, method and class of the library has a docstring (one summary line first).

The summary says what the object computes or is; where it implements an equation of the thesis the
docstring cites it ("Paper C eq. (25)"). Private names (a leading underscore) and functions nested in
functions are exempt.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("models", "fmus", "builder", "orchestrator")
DEFINITIONS = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)


def _public_definitions(tree: ast.Module, prefix: str = ""):
    """(qualified name, node) of every public definition at module level and in public classes."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, DEFINITIONS) and not node.name.startswith("_"):
            yield prefix + node.name, node
            if isinstance(node, ast.ClassDef):
                yield from _public_definitions(node, prefix + node.name + ".")


def _sources() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def test_the_packages_have_sources():
    assert len(_sources()) > 20


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_public_definition_has_a_docstring(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    missing = [f"{name} (line {node.lineno})" for name, node in _public_definitions(tree)
               if not (ast.get_docstring(node) or "").strip()]
    assert not missing, f"{path.relative_to(ROOT)}: no docstring on " + ", ".join(missing)


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_docstring_starts_with_a_summary_line(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    blank = [name for name, node in _public_definitions(tree)
             if (ast.get_docstring(node) or "x").splitlines()[0].strip() == ""]
    assert not blank, f"{path.relative_to(ROOT)}: docstring without a summary line on " + ", ".join(blank)
