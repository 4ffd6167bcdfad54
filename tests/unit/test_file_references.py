"""docs/case-reference.md, rig-reference.md, catenary-reference.md and sweep-reference.md are generated
from the declarations (models/schema.py) and are current; the loaders accept what the pages say."""
from __future__ import annotations

from pathlib import Path

import pytest

from pantohil.orchestrator.file_reference import COMMAND, PAGES, reference_markdown

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", list(PAGES))
def test_reference_is_current(name):
    page = (ROOT / "docs" / f"{name}.md").read_text(encoding="utf-8")
    assert page == reference_markdown(name), f"docs/{name}.md is stale: run {COMMAND}"


@pytest.mark.parametrize("name", list(PAGES))
def test_every_key_is_in_its_reference_with_its_range(name):
    schema, _ = PAGES[name]
    page = reference_markdown(name)
    for section in [*schema.sections, *schema.free_sections]:
        assert f"## [{section}]" in page, section
    for key in schema.all_keys():
        allowed = "true or false" if key.type is bool else key.param.range_text()
        assert f"| `{key.name}` | {key.param.unit if key.param.unit != '1' else ''} | {allowed}" in page, key.dotted


@pytest.mark.parametrize("name", list(PAGES))
def test_the_declared_defaults_validate(name):
    """Each file kind's declarations are consistent: every default lies in its key's range (a default
    outside would be refused if written out)."""
    schema, _ = PAGES[name]
    for key in schema.all_keys():
        if key.default is None or key.default == "auto" or not isinstance(key.default, (int, float)):
            continue
        if key.param.choices:
            assert key.default in key.param.choices, key.dotted
        else:
            assert key.param.contains(key.default), key.dotted
