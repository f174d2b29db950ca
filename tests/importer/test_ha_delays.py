"""Home Assistant's waits and tolerances imported: verify's delay (the read back after it),
the hub's delay after connecting, lazy_error_count (the device's offline threshold), each
bounded as the bridge bounds it and noted where it is not kept as written."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.importer.ha_modbus import import_ha
from bridge.importer.result import Import
from bridge.importer.source import load_source

HUB = {"name": "hub", "type": "tcp", "host": "127.0.0.1", "port": 502}


def convert(tmp_path: Path, hub: dict[str, Any]) -> Import:
    path = tmp_path / "configuration.yaml"
    path.write_text(yaml.safe_dump({"modbus": [HUB | hub]}, sort_keys=False), encoding="utf-8")
    return import_ha(load_source(path), path.name)


def notes(result: Import) -> list[tuple[str, bool, str]]:
    return [(n.key, n.partly, n.reason) for n in result.notes]


@pytest.mark.parametrize(
    ("delay", "kept", "noted"),
    [
        (2, 2, []),
        (0.5, 0.5, []),
        (
            90,
            60,
            [("Relay.verify.delay", True, "90 s: read back after 60 s, the bridge's longest wait")],
        ),
        ("soon", None, [("Relay.verify.delay", True, "'soon' is not seconds: read back at once")]),
    ],
)
def test_verify_delay(tmp_path: Path, delay: object, kept: float | None, noted: list[Any]) -> None:
    switch = {"name": "Relay", "address": 3, "slave": 1, "verify": {"delay": delay}}
    result = convert(tmp_path, {"switches": [switch]})
    (device,) = result.devices
    assert device.mapping["entities"]["relay"].get("verify_delay") == kept
    assert notes(result) == noted


@pytest.mark.parametrize(
    ("delay", "kept", "noted"),
    [
        (5, 5, []),
        (120, 60, [("hub.delay", True, "120 s: the bus waits 60 s, its longest")]),
        ("later", None, [("hub.delay", False, "'later' is not seconds")]),
    ],
)
def test_hub_delay(tmp_path: Path, delay: object, kept: float | None, noted: list[Any]) -> None:
    result = convert(
        tmp_path, {"delay": delay, "sensors": [{"name": "T", "address": 1, "slave": 1}]}
    )
    assert result.buses[0].get("connect_delay") == kept
    assert notes(result) == noted


def test_lazy_error_count_the_same_for_every_entity(tmp_path: Path) -> None:
    sensors = [{"name": f"S{n}", "address": n, "slave": 1, "lazy_error_count": 2} for n in range(3)]
    result = convert(tmp_path, {"sensors": sensors})
    assert result.devices[0].config["offline_after"] == 3
    assert notes(result) == []


def test_lazy_error_count_bounded_and_checked(tmp_path: Path) -> None:
    sensors = [
        {"name": "A", "address": 1, "slave": 1, "lazy_error_count": 500},
        {"name": "B", "address": 2, "slave": 1, "lazy_error_count": "many"},
    ]
    result = convert(tmp_path, {"sensors": sensors})
    assert result.devices[0].config["offline_after"] == 100
    assert notes(result) == [
        ("A.lazy_error_count", True, "500: offline after 100 failures, the most"),
        ("B.lazy_error_count", False, "'many' is not a count"),
        (
            "A.lazy_error_count",
            True,
            "the device goes offline after 100 failed requests in a row (the largest count "
            "+ 1): its entities' counts differ (0, 99)",
        ),
    ]
