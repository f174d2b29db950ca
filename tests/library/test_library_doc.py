"""docs/library.md is generated from the library (tools/library_doc.py) and current."""

from __future__ import annotations

from pathlib import Path

from bridge.core.mapping import shipped_library
from tests.factory import make_mapping
from tests.library.cross_check import compare
from tests.library.sources import SOURCES
from tools.library_doc import REGENERATE, render_library_doc

ROOT = Path(__file__).resolve().parent.parent.parent
DOC = ROOT / "docs" / "library.md"


def test_library_doc_is_current() -> None:
    assert DOC.read_text(encoding="utf-8") == render_library_doc(), (
        f"docs/library.md is out of date: run `make docs` (or `{REGENERATE}`)"
    )


def test_every_shipped_mapping_has_one_row_under_its_category_and_manufacturer() -> None:
    text = render_library_doc()
    for name, mapping in shipped_library().items():
        assert mapping.library is not None
        rows = [line for line in text.splitlines() if f"| `{name}` |" in line]
        assert len(rows) == 1, name
        category = text.index(
            f"\n## {mapping.library.category.value.replace('_', ' ').capitalize()}\n"
        )
        manufacturer = text.index(f"\n### {mapping.manufacturer}\n", category)
        assert category < manufacturer < text.index(rows[0])


def test_counts_and_choices_come_from_the_cross_check() -> None:
    text = render_library_doc()
    mapping = shipped_library()["eastron_sdm630"]
    row = next(line for line in text.splitlines() if "`eastron_sdm630`" in line)
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    comparisons = [compare(mapping, d) for d in SOURCES["eastron_sdm630"]]
    assert cells[5] == ", ".join(c.source for c in comparisons)
    assert cells[6] == ", ".join(f"{c.source} {c.compared}" for c in comparisons)
    assert all(c.compared > 0 for c in comparisons)
    assert cells[7] == str(sum(len(c.differences) for c in comparisons)) == "2"
    assert mapping.library is not None
    for row_ in mapping.library.disagreements:
        assert f"- `{row_.entity}` ({', '.join(row_.sources)}): " in text


def test_a_disagreement_is_listed_with_its_choice() -> None:
    entities = {"power": {"name": "Power", "table": "input", "address": 0, "type": "f32"}}
    library = {
        "category": "meter",
        "sources": ["mbmd"],
        "disagreements": [{"entity": "power", "sources": ["mbmd"], "choice": "the manual | wins"}],
    }
    meter = make_mapping(entities, protocol={"function_codes": [4]}, library=library)
    text = render_library_doc({"acme_m1": meter})
    assert "\n1 devices (meter: 1).\n" in text
    assert "- `power` (mbmd): the manual \\| wins" in text
    assert (
        "| T1 | `acme_m1` |  | rtu | test manual | none | 0 | 0 | medium | no fingerprint |" in text
    )
