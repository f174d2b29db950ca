"""What Home Assistant's modbus configs mean that the bridge now carries: a hub's delay after
connecting (``connect_delay``), a device's tolerance of failed reads (``offline_after``,
HA's ``lazy_error_count``), a switch's verify delay (``verify_delay``): the fields, their
bounds, and where they take effect."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from bridge.config import load_config_data
from bridge.core.health import DeviceHealth, HealthPolicy, Outcome, Transition
from bridge.errors import ConfigError
from bridge.modbus.engine import Engine
from bridge.modbus.scheduler import BusScheduler
from tests.factory import make_point
from tests.unit.test_scheduler import READ, ScriptedTransport, stop

BUS = {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": 1502}
DEVICE = {"id": "pump", "bus": "tcp", "unit": 1, "mapping": "nastec_vasco"}


def engine_of(bus: dict[str, Any], device: dict[str, Any]) -> Engine:
    return Engine(
        load_config_data({"buses": [BUS | bus], "devices": [DEVICE | device]}, Path("c.yaml"))
    )


def test_the_config_carries_connect_delay_and_offline_after() -> None:
    engine = engine_of({"connect_delay": "2s"}, {"offline_after": 11})
    assert engine.schedulers["tcp"].connect_delay == 2.0
    assert engine.devices["pump"].health.policy.offline_after == 11
    default = engine_of({}, {})
    assert default.schedulers["tcp"].connect_delay == 0.0
    assert default.devices["pump"].health.policy.offline_after == HealthPolicy().offline_after


@pytest.mark.parametrize(
    ("bus", "device", "message"),
    [
        ({"connect_delay": 61}, {}, "connect_delay"),
        ({"connect_delay": -1}, {}, "connect_delay"),
        ({}, {"offline_after": 0}, "offline_after"),
        ({}, {"offline_after": 101}, "offline_after"),
    ],
)
def test_out_of_bounds_is_refused_naming_the_field(
    bus: dict[str, Any], device: dict[str, Any], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        load_config_data({"buses": [BUS | bus], "devices": [DEVICE | device]}, Path("c.yaml"))


def test_offline_after_counts_failures_in_a_row() -> None:
    health = DeviceHealth(HealthPolicy(offline_after=4))
    assert health.record(Outcome.OK, 0.0) is Transition.ONLINE
    transitions = [health.record(Outcome.TIMEOUT, float(t)) for t in range(1, 5)]
    assert transitions == [None, None, None, Transition.OFFLINE]


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"access": "rw", "verify_delay": 61}, "less than or equal to 60"),
        ({"access": "rw", "verify_delay": 0}, "greater than 0"),
        ({"access": "rw", "verify": False, "verify_delay": 1}, "verify_delay delays"),
        ({"verify_delay": 1}, "verify_delay delays"),  # read-only: nothing is written
        ({"access": "w", "verify_delay": 1}, "verify_delay delays"),  # nothing to read back
    ],
)
def test_verify_delay_is_bounded_and_needs_a_read_back(
    fields: dict[str, Any], message: str
) -> None:
    with pytest.raises(ValidationError, match=message):
        make_point(**fields)
    assert make_point(access="rw", verify_delay="1.5s").entity.verify_delay == 1.5


@pytest.mark.asyncio
async def test_the_first_request_after_each_connect_waits_connect_delay() -> None:
    """A lower bound only (a sleep never ends early): the request goes out no sooner than
    ``connect_delay`` after the port opened, and again after the link was lost."""
    opened: list[float] = []
    transport = ScriptedTransport()
    plain_open = transport.open

    async def open_and_note() -> None:
        await plain_open()
        opened.append(time.monotonic())

    transport.open = open_and_note  # type: ignore[method-assign]
    scheduler = BusScheduler(transport, 0.0, connect_delay=0.2)  # type: ignore[arg-type]
    task = asyncio.create_task(scheduler.run())
    try:
        await scheduler.submit(1, READ, timeout=1)
        await scheduler.submit(1, READ, timeout=1)  # connected: no wait
        transport.close()  # the link is lost
        await scheduler.submit(1, READ, timeout=1)
    finally:
        await stop(task)
    sent = [at for _, _, at in transport.calls]
    assert len(opened) == 2
    assert sent[0] - opened[0] >= 0.2 * 0.99
    assert sent[2] - opened[1] >= 0.2 * 0.99
    assert sent[0] <= sent[1] < opened[1]


def test_a_device_that_reads_fewer_than_4_registers_cannot_have_a_64_bit_value(
    tmp_path: Path,
) -> None:
    mapping = tmp_path / "meter.yaml"
    mapping.write_text(
        "manufacturer: Test\nmodel: Meter\ndescription: x\nsource: {title: x}\n"
        "entities:\n  energy: {name: Energy, address: 0, type: u64}\n",
        encoding="utf-8",
    )
    device = DEVICE | {"mapping": str(mapping), "protocol": {"max_read_registers": 2}}
    with pytest.raises(ConfigError, match="max_read_registers: 2 would read the 64-bit energy"):
        load_config_data({"buses": [BUS], "devices": [device]}, tmp_path / "c.yaml")
