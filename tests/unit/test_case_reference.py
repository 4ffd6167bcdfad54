"""docs/case-reference.md is generated from the declarations (models/parameters.py) and is current."""
from __future__ import annotations

from pathlib import Path

from pantohil.models.case_reference import reference_markdown
from pantohil.models.parameters import all_keys

ROOT = Path(__file__).resolve().parents[2]


def test_case_reference_is_current():
    page = (ROOT / "docs" / "case-reference.md").read_text(encoding="utf-8")
    assert page == reference_markdown(), ("docs/case-reference.md is stale: run "
                                          "python -m pantohil.models.case_reference docs/case-reference.md")


def test_every_key_is_in_the_reference_with_its_range():
    page = reference_markdown()
    for key in all_keys():
        assert f"| `{key.name}` |" in page and key.param.range_text() in page, key.dotted
