"""The pure config diff (bridge/core/config_diff.py): every kind of change, one at a time
and together, and what each takes to apply."""

from __future__ import annotations

from dataclasses import replace

import pytest

from bridge.core.config_diff import ConfigDiff, ConfigView, DeviceView, diff_configs

PUMP = DeviceView(bus="rs485", enabled=True, settings={"unit": 1}, mapping="nastec")
DRIVE = DeviceView(bus="rs485", enabled=True, settings={"unit": 2}, mapping="vacon")
GENSET = DeviceView(bus="lan", enabled=True, settings={"unit": 1}, mapping="smartgen")
BASE = ConfigView(
    settings={"mqtt.url": "mqtt://a", "bridge.web": {"enabled": False}},
    buses={"rs485": {"port": "/dev/ttyUSB0"}, "lan": {"host": "10.0.0.2"}},
    devices={"pump": PUMP, "drive": DRIVE, "genset": GENSET},
)


def changed(**parts: object) -> ConfigView:
    """BASE with its parts replaced (dicts merged over BASE's)."""
    merged = {
        name: {**getattr(BASE, name), **value}  # type: ignore[dict-item]
        for name, value in parts.items()
    }
    return replace(BASE, **merged)


def without(section: str, *ids: str) -> ConfigView:
    kept = {k: v for k, v in getattr(BASE, section).items() if k not in ids}
    return replace(BASE, **{section: kept})


def test_the_same_config_is_no_change() -> None:
    diff = diff_configs(BASE, BASE)
    assert diff == ConfigDiff()
    assert diff.empty
    assert diff.describe() == "nothing"
    assert diff.summary() == {}


@pytest.mark.parametrize(
    ("new", "expected"),
    [
        (changed(devices={"well": PUMP}), ConfigDiff(added=("well",))),
        (without("devices", "drive"), ConfigDiff(removed=("drive",))),
        (
            changed(devices={"drive": replace(DRIVE, enabled=False)}),
            ConfigDiff(disabled=("drive",)),
        ),
        (
            changed(devices={"pump": replace(PUMP, settings={"unit": 3})}),
            ConfigDiff(restarted=("pump",)),
        ),
        (
            changed(devices={"pump": replace(PUMP, mapping="nastec2")}),
            ConfigDiff(restarted=("pump",)),
        ),
        (changed(devices={"pump": replace(PUMP, bus="lan")}), ConfigDiff(restarted=("pump",))),
        (changed(buses={"tcp2": {"host": "h"}}), ConfigDiff(buses_added=("tcp2",))),
        (
            changed(buses={"lan": {"host": "10.0.0.3"}}),
            ConfigDiff(buses_restarted=("lan",), restarted=("genset",)),
        ),
        (
            changed(buses={"rs485": {"port": "/dev/ttyUSB1"}}),
            ConfigDiff(buses_restarted=("rs485",), restarted=("drive", "pump")),
        ),
        (changed(settings={"mqtt.url": "mqtt://b"}), ConfigDiff(restart=("mqtt.url",))),
        (changed(settings={"mqtt.username": "x"}), ConfigDiff(restart=("mqtt.username",))),
        (
            replace(BASE, settings={"mqtt.url": "mqtt://a"}),
            ConfigDiff(restart=("bridge.web",)),
        ),
    ],
    ids=[
        "device added",
        "device removed",
        "device disabled",
        "settings changed",
        "mapping changed",
        "moved to another bus",
        "bus added",
        "bus changed restarts its devices",
        "serial bus changed restarts both",
        "a restart setting changed",
        "a restart setting appeared",
        "a restart setting went away",
    ],
)
def test_one_change_is_one_kind(new: ConfigView, expected: ConfigDiff) -> None:
    assert diff_configs(BASE, new) == expected
    assert not expected.empty


def test_a_disabled_device_enabled_is_started_not_added() -> None:
    off = changed(devices={"drive": replace(DRIVE, enabled=False)})
    diff = diff_configs(off, BASE)
    assert diff == ConfigDiff(enabled=("drive",))
    assert diff.started == ("drive",)
    assert diff.stopped == ()


def test_a_disabled_device_edited_or_removed_changes_nothing_running() -> None:
    off = changed(devices={"drive": replace(DRIVE, enabled=False)})
    edited = changed(devices={"drive": replace(DRIVE, enabled=False, settings={"unit": 9})})
    assert diff_configs(off, edited).empty
    gone = replace(off, devices={k: v for k, v in off.devices.items() if k != "drive"})
    assert diff_configs(off, gone).empty


def test_a_device_added_disabled_is_not_started() -> None:
    assert diff_configs(BASE, changed(devices={"well": replace(PUMP, enabled=False)})).empty


def test_an_id_change_is_the_old_removed_and_the_new_added() -> None:
    renamed = without("devices", "pump")
    renamed = replace(renamed, devices={**renamed.devices, "borehole": PUMP})
    diff = diff_configs(BASE, renamed)
    assert diff == ConfigDiff(added=("borehole",), removed=("pump",))
    assert diff.stopped == ("pump",)
    assert diff.started == ("borehole",)


def test_a_bus_removed_with_its_devices() -> None:
    new = replace(without("buses", "lan"), devices={"pump": PUMP, "drive": DRIVE})
    assert diff_configs(BASE, new) == ConfigDiff(buses_removed=("lan",), removed=("genset",))


def test_a_restarted_bus_does_not_restart_its_stopped_or_started_devices() -> None:
    new = changed(
        buses={"rs485": {"port": "/dev/ttyUSB1"}},
        devices={"drive": replace(DRIVE, enabled=False), "well": PUMP},
    )
    assert diff_configs(BASE, new) == ConfigDiff(
        buses_restarted=("rs485",), added=("well",), disabled=("drive",), restarted=("pump",)
    )


def test_everything_at_once_is_listed_and_described() -> None:
    new = changed(
        settings={"mqtt.url": "mqtt://b", "bridge.gateway": {"enabled": True}},
        buses={"tcp2": {"host": "h"}},
        devices={"pump": replace(PUMP, enabled=False), "well": GENSET},
    )
    new = replace(new, devices={k: v for k, v in new.devices.items() if k != "genset"})
    diff = diff_configs(BASE, new)
    assert diff.summary() == {
        "restart": ["bridge.gateway", "mqtt.url"],
        "buses_added": ["tcp2"],
        "added": ["well"],
        "removed": ["genset"],
        "disabled": ["pump"],
    }
    assert diff.describe() == (
        "needs a restart: bridge.gateway, mqtt.url; buses added: tcp2; devices added: well; "
        "devices removed: genset; devices disabled: pump"
    )
    assert diff.stopped == ("genset", "pump")


def test_the_diff_is_symmetric_in_what_starts_and_stops() -> None:
    new = changed(devices={"pump": replace(PUMP, enabled=False), "well": GENSET})
    forward, back = diff_configs(BASE, new), diff_configs(new, BASE)
    assert (forward.added, forward.disabled) == (back.removed, back.enabled)
