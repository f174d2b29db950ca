"""bridge.config.store: each change to a real, commented config file (examples/rtu-serial.
yaml) is exactly that change, comments and layout kept; what it refuses (a table of
hostile and invalid edits) names the field and leaves the file byte for byte; a file
changed on disk is never overwritten."""

from __future__ import annotations

import difflib
import shutil
from pathlib import Path
from typing import Any

import pytest

from bridge.config import load_config
from bridge.config.edits import parse_change
from bridge.config.store import ConfigStore
from bridge.errors import ConfigConflictError, ConfigEditError

EXAMPLES = Path(__file__).parents[2] / "examples"
PUMP_BLOCK = "  - id: borehole_pump\n    name: Borehole pump\n"


@pytest.fixture
def config(tmp_path: Path) -> Path:
    path = tmp_path / "config.yaml"
    shutil.copyfile(EXAMPLES / "rtu-serial.yaml", path)
    return path


def changed(before: str, after: str) -> tuple[list[str], list[str]]:
    """The lines removed from ``before`` and added in ``after``."""
    diff = list(difflib.unified_diff(before.splitlines(), after.splitlines(), lineterm="", n=0))
    removed = [line[1:] for line in diff if line.startswith("-") and not line.startswith("---")]
    added = [line[1:] for line in diff if line.startswith("+") and not line.startswith("+++")]
    return removed, added


def apply(path: Path, change: dict[str, Any]) -> str:
    ConfigStore.open(path).apply(parse_change(change))
    return path.read_text(encoding="utf-8")


def folder_files(path: Path) -> list[str]:
    return sorted(p.name for p in path.parent.iterdir())


EDITS = [
    pytest.param(
        {"name": "Well pump"},
        ["    name: Borehole pump"],
        ["    name: Well pump"],
        id="rename",
    ),
    pytest.param(
        {"poll.fast": "7s"},
        ["    poll: {fast: 5s, slow: 120s}"],
        ["    poll: {fast: 7s, slow: 120s}"],
        id="poll-fast-in-a-flow-mapping",
    ),
    pytest.param({"unit": 5}, ["    unit: 1"], ["    unit: 5"], id="unit"),
    pytest.param(
        {"enabled": False},
        [],
        ["    enabled: false"],
        id="disable-adds-a-key-before-the-blank-line",
    ),
    pytest.param(
        {"allow_dangerous_writes": True},
        [
            "    allow_dangerous_writes: false    # motor ratings, COMBO, passwords stay read-only in HA"
        ],
        [
            "    allow_dangerous_writes: true     # motor ratings, COMBO, passwords stay read-only in HA"
        ],
        id="dangerous-writes-comment-kept",
    ),
    pytest.param(
        {"options.family": "mida"},
        [
            "      family: vasco                  # mida for a MIDA (digital-input configuration bits)"
        ],
        [
            "      family: mida                   # mida for a MIDA (digital-input configuration bits)"
        ],
        id="option",
    ),
    pytest.param(
        {"id": "well_pump"}, ["  - id: borehole_pump"], ["  - id: well_pump"], id="new-id"
    ),
    pytest.param(
        {"allow_dangerous_writes": None},
        [
            "    allow_dangerous_writes: false    # motor ratings, COMBO, passwords stay read-only in HA"
        ],
        [],
        id="a-key-removed-leaves-the-blank-line-after-it",
    ),
    pytest.param(
        {"options": None},
        [
            "    options:",
            "      register_9f: pcb_temperature   # or input_current: which one your model has (keypad)",
            "      family: vasco                  # mida for a MIDA (digital-input configuration bits)",
            "      pv_input: absent               # present on a VASCO Solar (MPPT/PV registers)",
        ],
        [],
        id="a-section-removed-leaves-the-comments-after-it",
    ),
]


@pytest.mark.parametrize(("fields", "removed", "added"), EDITS)
def test_an_edit_changes_its_lines_only(
    config: Path, fields: dict[str, Any], removed: list[str], added: list[str]
) -> None:
    before = config.read_text(encoding="utf-8")
    after = apply(config, {"kind": "edit_device", "id": "borehole_pump", "set": fields})
    assert changed(before, after) == (removed, added)
    if fields == {"enabled": False}:  # in the pump's block, before the blank line
        assert "    enabled: false\n\n  - id: booster_starter" in after
    loaded = load_config(config)  # as the bridge loads it
    device = loaded.config.devices[0]
    for path, value in fields.items():
        if value is None:  # removed: the default applies
            continue
        field, _, key = path.partition(".")
        got = getattr(device, field)
        assert (got[key] if isinstance(got, dict) else getattr(got, key, got)) in (value, 7.0)


def test_the_loaded_config_returned_is_the_file_as_the_bridge_loads_it(config: Path) -> None:
    store = ConfigStore.open(config)
    applied = store.apply(parse_change({"kind": "remove_device", "id": "borehole_pump"}))
    assert applied.loaded.config == load_config(config).config
    assert [d.id for d in applied.loaded.config.devices] == ["booster_starter"]
    assert set(applied.loaded.mappings) == {"booster_starter"}
    assert applied.summary.splitlines() == [
        f"{config}: remove device borehole_pump",
        "  devices.borehole_pump: (removed)",
    ]


def test_removing_a_device_removes_its_block_and_comments_only(config: Path) -> None:
    before = config.read_text(encoding="utf-8")
    after = apply(config, {"kind": "remove_device", "id": "borehole_pump"})
    start = before.index(PUMP_BLOCK)
    end = before.index("  - id: booster_starter")
    assert after == before[:start] + before[end:]


def test_removing_the_last_device_removes_its_separator_too(config: Path) -> None:
    before = config.read_text(encoding="utf-8")
    after = apply(config, {"kind": "remove_device", "id": "booster_starter"})
    assert after == before[: before.index("\n  - id: booster_starter") + 1].rstrip("\n") + "\n"


def test_adding_a_device_appends_it_and_changes_nothing_else(config: Path) -> None:
    before = config.read_text(encoding="utf-8")
    device = {
        "id": "meter",
        "name": "on",  # YAML 1.1 would read a bare `on` as true
        "bus": "rs485",
        "unit": 3,
        "mapping": "soft_starter",
        "poll": {"fast": "10s"},
    }
    applied = ConfigStore.open(config).apply(parse_change({"kind": "add_device", "device": device}))
    after = config.read_text(encoding="utf-8")
    assert after == before + (  # spaced as the entries before it
        '\n  - id: meter\n    name: "on"\n    bus: rs485\n    unit: 3\n'
        "    mapping: soft_starter\n    poll:\n      fast: 10s\n"
    )
    assert applied.loaded.config.devices[-1].name == "on"
    assert "  devices.meter.unit: 3" in applied.summary.splitlines()


@pytest.mark.parametrize(
    ("bus", "lines"),
    [
        (
            {"id": "gw", "transport": "tcp", "host": "10.0.0.5", "tcp_port": 502},
            ["  - id: gw", "    transport: tcp", "    host: 10.0.0.5", "    tcp_port: 502"],
        ),
        (
            {"id": "line2", "transport": "rtu", "port": "/dev/ttyUSB1", "baudrate": 19200},
            [
                "  - id: line2",
                "    transport: rtu",
                "    port: /dev/ttyUSB1",
                "    baudrate: 19200",
            ],
        ),
    ],
    ids=["tcp", "serial"],
)
def test_adding_a_bus_puts_it_after_the_last_bus(
    config: Path, bus: dict[str, Any], lines: list[str]
) -> None:
    before = config.read_text(encoding="utf-8")
    after = apply(config, {"kind": "add_bus", "bus": bus})
    assert changed(before, after) == ([], lines)
    assert after.index(lines[0]) < after.index("\ndevices:")
    assert "    retries: 1\n" + "\n".join(lines) + "\n\ndevices:" in after
    assert [b.id for b in load_config(config).config.buses] == ["rs485", bus["id"]]


def test_flow_style_entries_stay_flow_style(tmp_path: Path) -> None:
    path = tmp_path / "config.yaml"
    shutil.copyfile(EXAMPLES / "config.yaml", path)
    before = path.read_text(encoding="utf-8")
    after = apply(path, {"kind": "edit_device", "id": "fan_drive", "set": {"name": "Fan"}})
    assert changed(before, after) == (
        ["  - {id: fan_drive, name: Fan drive, bus: sim, unit: 2, mapping: p2_vfd}"],
        ["  - {id: fan_drive, name: Fan, bus: sim, unit: 2, mapping: p2_vfd}"],
    )
    added = apply(
        path,
        {"kind": "add_device", "device": {"id": "m", "bus": "sim", "unit": 9, "mapping": "p2_vfd"}},
    )
    assert changed(after, added) == ([], ["  - {id: m, bus: sim, unit: 9, mapping: p2_vfd}"])
    # the genset's entry over two lines, with its comment, is as the user wrote it
    assert (
        "smartgen_hgm6100,\n     protocol: {min_request_interval: 0.2s}}   # a simulator" in added
    )


def test_a_new_id_renames_the_gateways_reference(tmp_path: Path) -> None:
    path = tmp_path / "config.yaml"
    path.write_text(
        "bridge:\n  gateway:\n    enabled: true\n    units: {1: pump}   # the pump for the PLC\n"
        "buses:\n  - {id: gw, transport: tcp, host: 127.0.0.1}\n"
        "devices:\n  - {id: pump, bus: gw, unit: 1, mapping: p2_vfd}\n",
        encoding="utf-8",
    )
    before = path.read_text(encoding="utf-8")
    after = apply(path, {"kind": "edit_device", "id": "pump", "set": {"id": "well"}})
    assert changed(before, after) == (
        [
            "    units: {1: pump}   # the pump for the PLC",
            "  - {id: pump, bus: gw, unit: 1, mapping: p2_vfd}",
        ],
        [
            "    units: {1: well}   # the pump for the PLC",
            "  - {id: well, bus: gw, unit: 1, mapping: p2_vfd}",
        ],
    )


def test_an_edit_of_a_shared_anchor_is_refused_not_spread(tmp_path: Path) -> None:
    path = tmp_path / "config.yaml"
    path.write_text(
        "buses: [{id: gw, transport: tcp, host: 127.0.0.1}]\n"
        "devices:\n"
        "  - {id: a, bus: gw, unit: 1, mapping: p2_vfd, poll: &poll {fast: 5s}}\n"
        "  - {id: b, bus: gw, unit: 2, mapping: p2_vfd, poll: *poll}\n",
        encoding="utf-8",
    )
    before = path.read_bytes()
    with pytest.raises(ConfigEditError, match="YAML anchor"):
        apply(path, {"kind": "edit_device", "id": "a", "set": {"poll.fast": "9s"}})
    assert path.read_bytes() == before
    after = apply(path, {"kind": "edit_device", "id": "a", "set": {"unit": 3}})  # the rest works
    assert changed(before.decode(), after) == (
        ["  - {id: a, bus: gw, unit: 1, mapping: p2_vfd, poll: &poll {fast: 5s}}"],
        ["  - {id: a, bus: gw, unit: 3, mapping: p2_vfd, poll: &poll {fast: 5s}}"],
    )


def test_a_file_changed_on_disk_is_not_overwritten(config: Path) -> None:
    store = ConfigStore.open(config)
    text = config.read_text(encoding="utf-8")
    changed_on_disk = text.replace("    unit: 2\n", "    unit: 3   # moved by hand\n")
    config.write_text(changed_on_disk, encoding="utf-8")
    files = folder_files(config)
    change = parse_change({"kind": "edit_device", "id": "borehole_pump", "set": {"name": "X"}})
    with pytest.raises(ConfigConflictError) as conflict:
        store.apply(change)
    assert config.read_text(encoding="utf-8") == changed_on_disk
    assert folder_files(config) == files
    diff = conflict.value.diff.splitlines()
    assert diff[:2] == ["--- config.yaml (read)", "+++ config.yaml (on disk)"]
    assert [line for line in diff if line[:1] in "+-" and line[:3] not in ("---", "+++")] == [
        "-    unit: 2",
        "+    unit: 3   # moved by hand",
    ]
    store.refresh()  # the page shows the difference, the user reloads and edits again
    store.apply(change)
    assert "    unit: 3   # moved by hand\n" in config.read_text(encoding="utf-8")
    assert "    name: X\n" in config.read_text(encoding="utf-8")


def test_preview_validates_and_writes_nothing(config: Path) -> None:
    before, files = config.read_bytes(), folder_files(config)
    store = ConfigStore.open(config)
    loaded = store.preview(
        parse_change({"kind": "edit_device", "id": "borehole_pump", "set": {"unit": 7}})
    )
    assert loaded.config.devices[0].unit == 7
    assert config.read_bytes() == before
    assert folder_files(config) == files
    with pytest.raises(ConfigEditError):
        store.preview(
            parse_change({"kind": "edit_device", "id": "borehole_pump", "set": {"unit": 2}})
        )


GOOD_EXAMPLES = sorted(p for p in EXAMPLES.glob("*.yaml") if p.name != "bad.yaml")


@pytest.mark.parametrize("example", GOOD_EXAMPLES, ids=lambda p: p.name)
def test_every_device_of_every_example_renames_in_its_own_lines(
    example: Path, tmp_path: Path
) -> None:
    path = tmp_path / example.name
    original = example.read_text(encoding="utf-8")
    devices = load_config(example).config.devices
    for device in devices:
        path.write_text(original, encoding="utf-8")
        after = apply(path, {"kind": "edit_device", "id": device.id, "set": {"name": "Renamed"}})
        removed, added = changed(original, after)
        assert len(removed) <= 2 and len(added) == 1, (device.id, removed, added)
        renamed = load_config(path).config.devices
        assert [d.model_copy(update={"name": None}) for d in renamed] == [
            d.model_copy(update={"name": None}) for d in devices
        ]
        assert next(d.name for d in renamed if d.id == device.id) == "Renamed"
