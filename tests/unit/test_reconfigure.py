"""A config applied live, the parts that need no bus nor broker: what the diff sees of a
loaded config (bridge/reconfigure.py), what it refuses, and the engine's guards kept
across a device's removal (bridge/modbus/engine.py)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from bridge.config import LoadedConfig, load_config_data
from bridge.core.config_diff import diff_configs
from bridge.modbus.engine import Engine
from bridge.reconfigure import SUNSPEC_BUILT, refusal, view_of

BUS = {"id": "lan", "transport": "tcp", "host": "127.0.0.1", "tcp_port": 1502}
STARTER = {"id": "starter", "bus": "lan", "unit": 3, "mapping": "soft_starter"}
INVERTER = {"id": "inverter", "bus": "lan", "unit": 2, "mapping": "sunspec"}


def loaded(*devices: dict[str, Any], **sections: Any) -> LoadedConfig:
    data = {"buses": [BUS], "devices": list(devices)} | sections
    return load_config_data(data, Path("/nonexistent/config.yaml"))


def test_the_view_names_every_restart_setting_and_holds_each_device() -> None:
    view = view_of(loaded(STARTER, INVERTER))
    assert {"mqtt.url", "mqtt.base_topic", "bridge.web", "bridge.gateway"} <= set(view.settings)
    assert all(name.split(".")[0] in ("mqtt", "bridge") for name in view.settings)
    assert set(view.buses) == {"lan"}
    starter = view.devices["starter"]
    assert (starter.bus, starter.enabled) == ("lan", True)
    assert starter.mapping is not None and starter.mapping != SUNSPEC_BUILT
    assert view.devices["inverter"].mapping == SUNSPEC_BUILT  # built at run time


def test_the_same_file_loaded_twice_is_no_change() -> None:
    assert diff_configs(view_of(loaded(STARTER)), view_of(loaded(STARTER))).empty


@pytest.mark.parametrize(
    ("sections", "named"),
    [
        ({"mqtt": {"base_topic": "site"}}, ["mqtt.base_topic"]),
        ({"mqtt": {"url": "mqtt://10.0.0.9:1883"}}, ["mqtt.url"]),
        ({"bridge": {"health_interval": 5}}, ["bridge.health_interval"]),
        (
            {"mqtt": {"discovery": "entity"}, "bridge": {"allow_raw_writes": True}},
            ["bridge.allow_raw_writes", "mqtt.discovery"],
        ),
    ],
)
def test_restart_settings_are_refused_by_name(sections: dict[str, Any], named: list[str]) -> None:
    old, new = loaded(STARTER), loaded(STARTER, **sections)
    diff = diff_configs(view_of(old), view_of(new))
    assert refusal(diff) == named


@pytest.mark.parametrize(
    ("before", "after", "expected"),
    [
        ((STARTER,), (STARTER, INVERTER), {"added": ["inverter"]}),
        ((STARTER, INVERTER), (STARTER,), {"removed": ["inverter"]}),
        (
            (STARTER, INVERTER),
            (STARTER, INVERTER | {"enabled": False}),
            {"disabled": ["inverter"]},
        ),
        ((STARTER, INVERTER), (STARTER, INVERTER | {"name": "Roof"}), {"restarted": ["inverter"]}),
    ],
    ids=["added", "removed", "disabled", "changed"],
)
def test_a_sunspec_device_is_applied_by_its_settings_not_its_built_mapping(
    before: tuple[dict[str, Any], ...],
    after: tuple[dict[str, Any], ...],
    expected: dict[str, list[str]],
) -> None:
    old, new = loaded(*before), loaded(*after)
    diff = diff_configs(view_of(old), view_of(new))
    assert diff.summary() == expected
    assert refusal(diff) == []


def test_a_device_removed_and_added_again_keeps_its_guard() -> None:
    """A guard only grows: the registers the first mapping guarded stay guarded under the
    same id, whatever mapping the device comes back with."""
    first = loaded(STARTER)
    again = loaded(STARTER | {"mapping": "vacon_nx"})
    engine = Engine(first)
    guarded = set(engine.devices["starter"].guard.dangerous)
    assert guarded

    asyncio.run(engine.remove_device("starter"))
    assert "starter" not in engine.devices
    poller = engine.add_device(again.config.devices[0], again.mappings["starter"])

    assert guarded <= set(poller.guard.dangerous)
    own = Engine(again).devices["starter"].guard.dangerous
    assert not guarded <= set(own)  # kept, not the new mapping's own


def test_buses_added_and_removed_before_the_engine_runs() -> None:
    engine = Engine(loaded(STARTER))
    other = loaded(STARTER).config.buses[0].model_copy(update={"id": "rs485"})
    engine.add_bus(other)
    assert sorted(engine.schedulers) == ["lan", "rs485"]
    asyncio.run(engine.remove_bus("rs485"))
    assert sorted(engine.schedulers) == ["lan"]
