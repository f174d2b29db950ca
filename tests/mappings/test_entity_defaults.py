"""Which entities Home Assistant shows, and where (docs/mappings.md, "Which entities are
enabled"): the rule on what discovery sends for every shipped mapping, every option
combination. ``pytest -s`` prints the counts per device and category."""

from __future__ import annotations

import json
from collections import Counter
from typing import Any

import pytest

from bridge.core.discovery import (
    BUS_HEALTH_SENSORS,
    DEVICE_HEALTH_SENSORS,
    DeviceInfo,
    Origin,
    build_bridge_discovery,
    build_device_discovery,
)
from bridge.core.mapping import Mapping
from bridge.core.topics import Topics
from tests.mappings.test_shipped import MAPPINGS, combinations

TOPICS = Topics(base="modbus")
CATEGORIES = ("none", "config", "diagnostic")


def components(
    name: str, options: dict[str, str], *, dangerous: bool = False
) -> dict[str, dict[str, Any]]:
    device = DeviceInfo(
        id=name,
        name=name,
        mapping=MAPPINGS[name],
        options=options,
        bus="rs485",
        unit=1,
        allow_dangerous_writes=dangerous,
        fast_interval=2.0,
        slow_interval=60.0,
    )
    cmps = build_device_discovery(device, TOPICS, Origin(), health=True)["cmps"]
    return {k: c for k, c in cmps.items() if c["platform"] != "device_automation"}  # entities


def reason_for(mapping: Mapping, options: dict[str, str], key: str) -> str | None:
    """The mapping's reason, or the health sensor's (``device_<id>_<suffix>``)."""
    entity = mapping.active(options).get(key)
    if entity is not None:
        return entity.ha.enabled_reason
    health = (s for s in DEVICE_HEALTH_SENSORS if key.endswith(f"_{s.suffix}"))
    return next(health).enabled_reason


@pytest.mark.parametrize("dangerous", [False, True])
@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_a_diagnostic_entity_is_enabled_only_for_a_reason(name: str, dangerous: bool) -> None:
    mapping = MAPPINGS[name]
    for options in combinations(mapping):
        for key, config in components(name, options, dangerous=dangerous).items():
            if config.get("entity_category") == "diagnostic" and config["enabled_by_default"]:
                assert reason_for(mapping, options, key), (options, key)


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_a_commissioning_setting_is_disabled_when_it_can_be_written(name: str) -> None:
    mapping = MAPPINGS[name]
    for options in combinations(mapping):
        active = mapping.active(options)
        for key, config in components(name, options, dangerous=True).items():
            entity = active.get(key)
            if entity is not None and entity.dangerous and config.get("entity_category"):
                assert not config["enabled_by_default"] or entity.ha.enabled_reason, key


def test_the_bridge_enables_its_connection_and_bus_sensors_for_a_reason() -> None:
    [message] = build_bridge_discovery(TOPICS, Origin(), "modbus", buses=["rs485"])
    reasons = {f"bus_rs485_{s.suffix}": s.enabled_reason for s in BUS_HEALTH_SENSORS}
    for key, config in json.loads(message.payload)["cmps"].items():
        assert config["entity_category"] == "diagnostic", key
        if config["enabled_by_default"] and key != "connection_state":
            assert reasons[key], key


def test_the_counts_per_device_and_category() -> None:
    """Not an assertion on the counts: a table to read (``pytest -s``)."""
    lines = [f"{'mapping':18} {'enabled':>8} {'of':>4}  " + "  ".join(CATEGORIES)]
    for name in sorted(MAPPINGS):
        counts: Counter[tuple[str, bool]] = Counter()
        for config in components(name, {}).values():
            counts[(config.get("entity_category") or "none", config["enabled_by_default"])] += 1
        enabled = sum(n for (_, on), n in counts.items() if on)
        shown = [
            f"{counts[(c, True)]}/{counts[(c, True)] + counts[(c, False)]}" for c in CATEGORIES
        ]
        lines.append(f"{name:18} {enabled:8} {counts.total():4}  " + "  ".join(shown))
    print("\n" + "\n".join(lines))
    assert len(lines) == len(MAPPINGS) + 1
