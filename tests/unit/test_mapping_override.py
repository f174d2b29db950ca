"""Override files (``extends:``): a user mapping adds entities to a base and changes its
presentation, never a guard; the merged mapping loads as the flat file of its content."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.core.mapping import load_mapping, parse_mapping
from bridge.errors import MappingError

BASE = {
    "manufacturer": "Test",
    "model": "T1",
    "description": "test device",
    "source": {"title": "test manual"},
    "entities": {
        "reset": {"name": "Reset", "address": 1, "access": "rw", "dangerous": True},
        "password": {"name": "Password", "address": 2, "access": "rw", "secret": True},
        "command": {"name": "Command", "address": 3, "access": "w"},
        "voltage": {"name": "Voltage", "address": 4, "scale": 0.1, "unit": "V"},
        "speed": {"name": "Speed", "address": 5, "type": "s16", "access": "rw",
                  "dangerous_below": 0},
        "mode": {"name": "Mode", "address": 6, "access": "rw", "requires": {"voltage_ok": True}},
        "voltage_ok": {"name": "Voltage ok", "address": 4, "bit": 0},
        "setpoint": {"name": "Setpoint", "address": 7, "access": "rw", "min": 0, "max": 100},
        "energy": {"name": "Energy", "address": 10, "type": "u32"},
    },
}  # fmt: skip


def write(folder: Path, name: str, data: dict[str, Any]) -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def override(folder: Path, entities: dict[str, Any], **top: Any) -> Path:
    write(folder, "base.yaml", BASE)
    return write(folder, "mine.yaml", {"extends": "base.yaml", **top, "entities": entities})


def refusal(path: Path) -> list[str]:
    with pytest.raises(MappingError) as caught:
        load_mapping(path)
    assert caught.value.source == str(path)  # the override file is named
    return list(caught.value.issues)


def test_an_override_adds_an_entity_read_only_and_renames_one(tmp_path: Path) -> None:
    path = override(
        tmp_path,
        {
            "current": {"name": "Current", "address": 8, "scale": 0.01, "unit": "A"},
            "voltage": {"name": "Line voltage", "ha": {"device_class": "voltage"}},
        },
    )
    mapping = load_mapping(path)
    assert mapping.entities["current"].writable is False
    assert mapping.entities["voltage"].name == "Line voltage"
    assert mapping.entities["voltage"].ha.device_class == "voltage"
    assert mapping.entities["voltage"].scale == 0.1  # the rest is the base's


@pytest.mark.parametrize(
    ("key", "fields", "row"),
    [
        ("reset", {"dangerous": False}, "entities.reset.dangerous: the base marks it dangerous"),
        ("reset", {"access": "r", "dangerous": False}, "entities.reset.dangerous: the base"),
        ("password", {"secret": False}, "entities.password.secret: the base marks it secret"),
        ("command", {"access": "rw"}, "entities.command.access: the base marks it write-only"),
        ("voltage", {"access": "rw"}, "entities.voltage.access: the base marks it read-only"),
        ("speed", {"dangerous_below": None}, "entities.speed.dangerous_below: the base marks"),
        ("mode", {"requires": {}}, "entities.mode.requires: the base marks it guarded"),
        ("setpoint", {"max": 1000}, "entities.setpoint.max: an override may change only"),
        ("setpoint", {"address": 9}, "entities.setpoint.address: an override may change only"),
        ("voltage", {"ha": {"component": "number"}}, "entities.voltage.ha.component: an override"),
        ("voltage", {"scale": 1}, "entities.voltage.scale: an override may change only"),
    ],
)
def test_no_override_weakens_a_guard(
    tmp_path: Path, key: str, fields: dict[str, Any], row: str
) -> None:
    rows = refusal(override(tmp_path, {key: fields}))
    assert any(r.startswith(row) for r in rows), rows


@pytest.mark.parametrize(
    ("key", "fields", "dangerous", "writable"),
    [
        ("setpoint", {"dangerous": True}, True, True),
        ("setpoint", {"access": "r"}, False, False),
        ("reset", {"dangerous": True}, True, True),  # as the base says: no change
    ],
)
def test_an_override_may_guard_more(
    tmp_path: Path, key: str, fields: dict[str, Any], dangerous: bool, writable: bool
) -> None:
    entity = load_mapping(override(tmp_path, {key: fields})).entities[key]
    assert (entity.dangerous, entity.writable) == (dangerous, writable)


@pytest.mark.parametrize(
    ("address", "access", "row"),
    [
        (1, "r", "address: holding 1 (wire) is the base's reset, dangerous: a new entity may not"),
        (2, "r", "address: holding 2 (wire) is the base's password, secret: a new entity may not"),
        (3, "r", "address: holding 3 (wire) is the base's command, write-only: a new entity may"),
        (5, "rw", "address: holding 5 (wire) is the base's speed, guarded: a new entity may not"),
        (6, "r", "address: holding 6 (wire) is the base's mode, guarded: a new entity may not"),
        (4, "rw", "access: holding 4 (wire) is the base's voltage_ok, read-only: a new entity"),
        (
            {"address": 20, "write_address": 1},
            "rw",
            "write_address: holding 1 (wire) is the "
            "base's reset, dangerous: a new entity may not read or write it",
        ),
    ],
)
def test_a_new_entity_on_a_guarded_register_is_refused(
    tmp_path: Path, address: int | dict[str, int], access: str, row: str
) -> None:
    at = address if isinstance(address, dict) else {"address": address}
    new = {"name": "Raw word", "access": access} | at
    rows = refusal(override(tmp_path, {"raw": new}))
    assert len(rows) == 1 and rows[0].startswith("entities.raw." + row), rows


def test_a_new_read_only_entity_beside_a_read_only_one_is_taken(tmp_path: Path) -> None:
    new = {"name": "Voltage raw", "address": 4}
    assert (
        not load_mapping(override(tmp_path, {"voltage_raw": new})).entities["voltage_raw"].writable
    )


def test_a_new_writable_entity_on_a_free_register_is_taken(tmp_path: Path) -> None:
    new = {"name": "Spare", "address": 20, "access": "rw", "min": 0, "max": 10}
    assert load_mapping(override(tmp_path, {"spare": new})).entities["spare"].writable


def test_overlap_checks_run_on_the_merged_mapping(tmp_path: Path) -> None:
    new = {"name": "Wide", "address": 11, "type": "u32"}  # crosses energy's second word
    rows = refusal(override(tmp_path, {"wide": new}))
    assert rows and all("wide" in r or "energy" in r for r in rows), rows


@pytest.mark.parametrize(
    ("top", "row"),
    [
        ({"protocol": {"addressing": {"offset": 1}}}, "protocol: an override file holds only"),
        ({"status": "voltage"}, "status: an override file holds only"),
    ],
)
def test_an_override_holds_only_entities(tmp_path: Path, top: dict[str, Any], row: str) -> None:
    assert refusal(override(tmp_path, {}, **top)) == [row + " extends and entities"]


def test_one_level_only_and_a_missing_base_is_named(tmp_path: Path) -> None:
    first = override(tmp_path, {})
    second = write(tmp_path, "second.yaml", {"extends": first.name, "entities": {}})
    assert any("one level only" in r for r in refusal(second))
    lost = write(tmp_path, "lost.yaml", {"extends": "nowhere.yaml", "entities": {}})
    assert any(r.startswith("extends: no shipped mapping") for r in refusal(lost))


def test_an_override_loads_as_the_flat_file_of_its_content(tmp_path: Path) -> None:
    entities = {
        "spare": {"name": "Spare", "address": 0x62, "scale": 0.1, "unit": "V"},
        "power": {"name": "Power drawn", "poll": "slow"},
    }
    path = write(tmp_path, "pump.yaml", {"extends": "nastec_vasco", "entities": entities})
    merged = load_mapping(path)
    base = yaml.safe_load(Path(load_mapping.__code__.co_filename).parents[2].joinpath(
        "mappings", "nastec_vasco.yaml").read_text(encoding="utf-8"))  # fmt: skip
    flat = dict(base, entities=dict(base["entities"]))
    flat.pop("library")
    flat["entities"]["spare"] = entities["spare"]
    flat["entities"]["power"] = base["entities"]["power"] | {
        "name": "Power drawn", "poll": "slow"
    }  # fmt: skip
    alone = parse_mapping(yaml.safe_dump(flat), "flat.yaml")
    assert merged == alone
    assert merged.points() == alone.points()
    assert merged.points({"family": "mida"}) == alone.points({"family": "mida"})


def test_entities_of_an_override_are_a_mapping_of_fields(tmp_path: Path) -> None:
    path = write(tmp_path, "base.yaml", BASE)
    path = write(tmp_path, "mine.yaml", {"extends": path.name, "entities": ["voltage"]})
    assert refusal(path) == ["entities: a mapping of entity key -> fields"]


@pytest.mark.parametrize(
    ("fields", "row"),
    [
        ({"name": "No address"}, "entities.raw.address: Field required"),
        ({"name": "Far", "address": 70000, "access": "rw"}, "entities.raw.address: "),
    ],
)
def test_a_new_entity_is_checked_by_the_loader(
    tmp_path: Path, fields: dict[str, Any], row: str
) -> None:
    rows = refusal(override(tmp_path, {"raw": fields}))
    assert any(r.startswith(row) for r in rows), rows


def test_a_bad_extends_or_a_bad_base_is_named(tmp_path: Path) -> None:
    odd = write(tmp_path, "odd.yaml", {"extends": 5, "entities": {}})
    assert refusal(odd) == ["extends: a shipped mapping name or a .yaml path"]
    broken = write(tmp_path, "broken.yaml", BASE | {"entities": {"x": {"name": "X"}}})
    bad = write(tmp_path, "bad.yaml", {"extends": broken.name, "entities": {}})
    assert refusal(bad) == [f"extends: {broken}: entities.x.address: Field required"]
    (tmp_path / "text.yaml").write_text("a: [", encoding="utf-8")
    unparsed = write(tmp_path, "unparsed.yaml", {"extends": "text.yaml", "entities": {}})
    assert refusal(unparsed)[0].startswith("extends: text.yaml: ")
