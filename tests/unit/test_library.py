"""The device library's layout: the ``library:`` block, names found at any depth of the
shipped folder, a duplicate name refused naming both files, a nested name resolved like a
seed's."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.config import load_config_data
from bridge.core import mapping as mapping_module
from bridge.core.library import Category
from bridge.core.mapping import (
    builtin_mapping_names,
    builtin_mapping_path,
    check_mapping_text,
    in_library,
    library_index,
    mappings_folder,
    resolve_mapping_path,
    shipped_library,
)
from bridge.errors import MappingError

SEEDS = {
    "nastec_vasco": Category.PUMP,
    "p2_vfd": Category.DRIVE,
    "smartgen_hgm6100": Category.GENSET,
    "soft_starter": Category.MOTOR_STARTER,
    "vacon_nx": Category.DRIVE,
}

METER = """manufacturer: Acme
model: M1
description: a meter
source: {title: M1 register map, version: "2.1", url: "https://example.com/m1.pdf"}
protocol: {function_codes: [4], transports: [rtu, tcp]}
library:
  category: meter
  aliases: [M1-Modbus]
  sources: [mbmd]
  confidence: high
  disagreements:
    - {entity: %s, sources: [%s], choice: the document prints 0x0000}
entities:
  voltage: {name: Voltage, table: input, address: 0, type: f32, unit: V}
"""


def errors(text: str) -> tuple[str, ...]:
    return check_mapping_text(text, "m1.yaml").errors


def test_a_library_block_validates_and_keeps_its_facts() -> None:
    report = check_mapping_text(METER % ("voltage", "mbmd"), "m1.yaml")
    assert report.errors == ()
    assert report.mapping is not None and report.mapping.library is not None
    library = report.mapping.library
    assert (library.category, library.aliases, library.confidence) == (
        Category.METER,
        ("M1-Modbus",),
        "high",
    )
    assert report.mapping.source.version == "2.1"
    assert report.mapping.source.url == "https://example.com/m1.pdf"


def test_a_disagreement_names_an_entity_and_a_listed_source() -> None:
    assert errors(METER % ("current", "mbmd")) == (
        "library.disagreements.0.entity: no entity 'current'",
    )
    assert errors(METER % ("voltage", "evcc")) == (
        "library.disagreements.0.sources: 'evcc' is not in library.sources",
    )
    assert errors(METER % ("voltage", "vendor")) == ()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("  transports: [rtu]\n", "library: transports: what the device speaks is protocol."),
        ("  document: {title: x}\n", "library: document: the register document is the mapping's"),
        ("  category: fridge\n", "library.category: Input should be 'meter', 'inverter'"),
    ],
)
def test_misplaced_or_unknown_fields_are_refused_saying_why(extra: str, message: str) -> None:
    text = (METER % ("voltage", "mbmd")).replace(
        "  category: meter\n", "  category: meter\n" + extra
    )
    if "fridge" in extra:
        text = text.replace("  category: meter\n", "")
    assert any(row.startswith(message) for row in errors(text)), errors(text)


def test_every_shipped_mapping_has_its_index_entry() -> None:
    library = shipped_library()
    assert set(SEEDS) <= set(library)
    for name, category in SEEDS.items():
        entry = library[name].library
        assert entry is not None and entry.category is category, name
        assert library_index()[name] == mappings_folder() / f"{name}.yaml"
    assert all(m.library is not None for m in library.values())


def test_names_are_found_at_any_depth(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "mappings"
    (folder / "library" / "meter").mkdir(parents=True)
    seed = folder / "seed.yaml"
    nested = folder / "library" / "meter" / "acme_m1.yaml"
    seed.write_text(METER % ("voltage", "mbmd"))
    nested.write_text(METER % ("voltage", "mbmd"))
    (folder / "library" / "meter" / "notes.txt").write_text("not a mapping")
    monkeypatch.setattr(mapping_module, "mappings_folder", folder.resolve)
    assert builtin_mapping_names() == ["acme_m1", "seed"]
    assert builtin_mapping_path("acme_m1") == nested.resolve()
    assert resolve_mapping_path("acme_m1") == nested.resolve()
    assert in_library(nested) and in_library(seed)
    assert not in_library(tmp_path / "elsewhere.yaml")


def test_a_nested_name_works_in_a_config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "mappings"
    (folder / "library" / "meter").mkdir(parents=True)
    (folder / "library" / "meter" / "acme_m1.yaml").write_text(METER % ("voltage", "mbmd"))
    monkeypatch.setattr(mapping_module, "mappings_folder", folder.resolve)
    data = {
        "mqtt": {"url": "mqtt://127.0.0.1:1883"},
        "buses": [{"id": "line", "transport": "tcp", "host": "127.0.0.1", "tcp_port": 502}],
        "devices": [{"id": "meter", "bus": "line", "unit": 1, "mapping": "acme_m1"}],
    }
    loaded = load_config_data(data, tmp_path / "config.yaml")
    assert loaded.mappings["meter"].model == "M1"


def test_a_duplicate_name_is_an_error_naming_both_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "mappings"
    for category in ("meter", "inverter"):
        (folder / "library" / category).mkdir(parents=True)
        (folder / "library" / category / "acme_m1.yaml").write_text(METER % ("voltage", "mbmd"))
    monkeypatch.setattr(mapping_module, "mappings_folder", folder.resolve)
    with pytest.raises(MappingError) as refused:
        builtin_mapping_names()
    message = str(refused.value)
    assert str(folder.resolve() / "library" / "inverter" / "acme_m1.yaml") in message
    assert str(folder.resolve() / "library" / "meter" / "acme_m1.yaml") in message


def test_a_library_meter_is_named_in_a_config_like_a_seed(tmp_path: Path) -> None:
    data = {
        "mqtt": {"url": "mqtt://127.0.0.1:1883"},
        "buses": [{"id": "line", "transport": "rtu", "port": "/dev/ttyUSB0"}],
        "devices": [
            {"id": "grid", "bus": "line", "unit": 1, "mapping": "eastron_sdm630"},
            {"id": "pump", "bus": "line", "unit": 2, "mapping": "nastec_vasco"},
        ],
    }
    loaded = load_config_data(data, tmp_path / "config.yaml")
    assert loaded.mappings["grid"].model == "SDM630-Modbus V2"
    assert resolve_mapping_path("eastron_sdm630") == (
        mappings_folder() / "library" / "meter" / "eastron_sdm630.yaml"
    )


def test_a_shipped_mapping_without_its_index_entry_breaks_a_convention() -> None:
    text = (
        (METER % ("voltage", "mbmd")).split("library:")[0]
        + "entities:"
        + (METER.split("entities:")[1])
    )
    report = check_mapping_text(text, "m1.yaml", library=True)
    assert report.errors == ()
    assert report.warnings == (
        "library: a shipped mapping has its index entry (docs/mappings.md, Library)",
    )
    assert check_mapping_text(text, "m1.yaml").warnings == ()  # a user's own: nothing


def test_no_two_shipped_mappings_answer_to_one_name() -> None:
    """A model or an alias (case, spaces and dashes ignored) names one mapping, so
    ``mappings show SDM630`` is never ambiguous."""
    owners: dict[str, str] = {}
    for name, mapping in shipped_library().items():
        assert mapping.library is not None
        for alias in {mapping.model, *mapping.library.aliases}:
            plain = "".join(c for c in alias.lower() if c.isalnum())
            assert owners.setdefault(plain, name) == name, (alias, owners[plain], name)
