"""bridge.config.store refuses, in a hostile-input table: each change that is invalid as
``check`` sees it, or past a bound (a 1 MB name, deep or huge values), or naming what is
not there, raises ConfigEditError naming the field, and the file, its folder (no backup,
no temp file) and the store are as they were."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest

from bridge.config.edits import parse_change
from bridge.config.store import ConfigStore
from bridge.errors import ConfigEditError

EXAMPLES = Path(__file__).parents[2] / "examples"


@pytest.fixture
def config(tmp_path: Path) -> Path:
    path = tmp_path / "config.yaml"
    shutil.copyfile(EXAMPLES / "rtu-serial.yaml", path)
    return path


def folder_files(path: Path) -> list[str]:
    return sorted(p.name for p in path.parent.iterdir())


HUGE = "x" * 1_000_000
REFUSED = [
    # (change, the field named, words of the message)
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"unit": 300}},
        "devices.borehole_pump.unit",
        "less than or equal to 255",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"unit": 250}},
        "devices.borehole_pump.unit",
        "1..247",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"unit": 0}},
        "devices.borehole_pump.unit",
        "greater than or equal to 1",
    ),
    (
        {"kind": "edit_device", "id": "booster_starter", "set": {"unit": 1}},
        "devices.booster_starter.unit",
        "unit 1 is also 'borehole_pump'",
    ),
    (
        {"kind": "edit_device", "id": "booster_starter", "set": {"id": "borehole_pump"}},
        "devices.borehole_pump",
        "id used 2 times",
    ),
    (
        {
            "kind": "add_device",
            "device": {"id": "borehole_pump", "bus": "rs485", "unit": 9, "mapping": "p2_vfd"},
        },
        "devices.borehole_pump",
        "id used 2 times",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"mapping": "no_such_mapping"}},
        "devices.borehole_pump.mapping",
        "no_such_mapping",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"bus": "nowhere"}},
        "devices.borehole_pump.bus",
        "no bus 'nowhere'",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"name": HUGE}},
        "device.name",
        "at most 100 characters",
    ),
    (
        {
            "kind": "add_device",
            "device": {"id": "m", "name": HUGE, "bus": "rs485", "unit": 9, "mapping": "p2_vfd"},
        },
        "device.name",
        "at most 100 characters",
    ),
    ({"kind": "edit_device", "id": HUGE, "set": {"unit": 2}}, "id", "at most 64 characters"),
    (
        {"kind": "edit_device", "id": "nobody", "set": {"unit": 2}},
        "devices.nobody",
        "no device 'nobody'",
    ),
    ({"kind": "remove_device", "id": "nobody"}, "devices.nobody", "no device 'nobody'"),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"colour": "red"}},
        "device.colour",
        "not a device field",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"id": "Pump!"}},
        "devices.Pump!.id",
        "lowercase letters",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"poll.fast": "-2s"}},
        "devices.borehole_pump.poll.fast",
        "",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"options.family": "other"}},
        "devices.borehole_pump.options.family",
        "not one of",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"enabled": float("nan")}},
        "device.enabled",
        "not a finite number",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"options": {"k": [[[[["deep"]]]]]}}},
        "device.options.k.0.0.0",
        "nested more than 4",
    ),
    (
        {"kind": "add_bus", "bus": {"id": "rs485", "transport": "tcp", "host": "h"}},
        "buses.rs485",
        "id used 2 times",
    ),
    (
        {"kind": "add_bus", "bus": {"id": "x", "transport": "carrier-pigeon"}},
        "buses.x",
        "transport",
    ),
    (
        {"kind": "add_bus", "bus": {"id": "x", "transport": "tcp", "host": "h", "tcp_port": 70000}},
        "buses.x.tcp.tcp_port",
        "65535",
    ),
    ({"kind": "drop_table", "id": "x"}, "", "kind"),
    ("not a change", "", "valid dictionary"),
    (
        {
            "kind": "add_device",
            "device": {"id": "m", "options": {f"k{i}": [1] * 200 for i in range(200)}},
        },
        "device",
        "more than 2000 values",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"options.family": list(range(300))}},
        "device.options.family",
        "at most 256 entries",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"unit": 10**30}},
        "device.unit",
        "beyond 64 bits",
    ),
    (
        {
            "kind": "edit_device",
            "id": "borehole_pump",
            "set": {f"options.k{i}": "a" for i in range(65)},
        },
        "set",
        "at most 64",
    ),
    ({"kind": "edit_device", "id": "borehole_pump", "set": {}}, "set", "at least 1"),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"options.a\x00": "x"}},
        "device.options.a\x00",
        "not a device field",
    ),
    (
        {
            "kind": "add_device",
            "device": {
                "id": "m",
                "bus": "rs485",
                "unit": 9,
                "mapping": "p2_vfd",
                "password": "**********",
            },
        },
        "device.password",
        "give the secret itself",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"name": "a\x00b"}},
        "device.name",
        "no control",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"name": "two\nlines"}},
        "device.name",
        "no control",
    ),
    (
        {"kind": "edit_device", "id": "borehole_pump", "set": {"options": {"a\nb": "x"}}},
        "device.options",
        "keys are text",
    ),
]


@pytest.mark.parametrize(("change", "field", "words"), REFUSED, ids=lambda v: str(v)[:40])
def test_a_refused_edit_names_its_field_and_writes_nothing(
    config: Path, change: Any, field: str, words: str
) -> None:
    before = config.read_bytes()
    files = folder_files(config)
    store = ConfigStore.open(config)
    with pytest.raises(ConfigEditError) as refused:
        store.apply(parse_change(change))
    assert refused.value.field == field
    assert words in refused.value.message
    assert len(str(refused.value)) < 2000  # a 1 MB input is not echoed back
    assert config.read_bytes() == before
    assert folder_files(config) == files  # no backup, no temp file
    valid = {"kind": "edit_device", "id": "booster_starter", "set": {"unit": 3}}
    store.apply(parse_change(valid))  # the store is as it was: the next edit is made alone
    assert config.read_bytes() == before.replace(b"    unit: 2\n", b"    unit: 3\n")
