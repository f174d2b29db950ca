"""A Modbus TCP gateway whose serial side is the bus: ``serial_behind`` plans for that line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from bridge.config import TcpBus, load_config_data
from bridge.core.planner import limits_for, plan_reads
from bridge.core.timing import LinkTiming
from bridge.errors import ConfigError
from bridge.modbus.engine import bus_scheduler, link_timing
from tests.factory import make_mapping

NINE_SIX = LinkTiming.for_serial(9600)

# Four small groups of registers spread over 250 addresses, the holes readable: over TCP a
# few long reads across the holes are cheapest, on a 9600 baud line four tight reads are.
SPREAD = make_mapping(
    {
        f"r{group}_{i}": {"name": f"R{group} {i}", "address": 80 * group + i}
        for group in range(4)
        for i in range(4)
    },
    protocol={"readable_gaps": True, "max_read_registers": 125},
)


def bus(**fields: Any) -> TcpBus:
    data = {"id": "gw", "transport": "tcp", "host": "192.0.2.10"} | fields
    return TcpBus.model_validate(data)


def serial_ms(reads: tuple[Any, ...]) -> float:
    return 1000 * sum(NINE_SIX.read_cost(r) for r in reads)


def test_a_gateway_without_its_serial_line_plans_for_the_network() -> None:
    assert link_timing(bus()) == LinkTiming(mode="tcp")
    plan = plan_reads(SPREAD.points().values(), limits_for(SPREAD, timing=link_timing(bus())))
    assert len(plan.reads) == 2  # across the holes: one round trip each


def test_the_serial_line_behind_a_gateway_is_what_the_plan_saves() -> None:
    gateway = bus(serial_behind={"baudrate": 9600})
    assert link_timing(gateway) == NINE_SIX
    tight = plan_reads(SPREAD.points().values(), limits_for(SPREAD, timing=link_timing(gateway)))
    assert [(r.address, r.count) for r in tight.reads] == [(80 * g, 4) for g in range(4)]
    across = plan_reads(SPREAD.points().values(), limits_for(SPREAD, timing=LinkTiming("tcp")))
    assert serial_ms(tight.reads) < serial_ms(across.reads) / 2


@pytest.mark.parametrize(("transport", "gap"), [("tcp", 0.0), ("rtu-over-tcp", NINE_SIX.silence)])
def test_a_transparent_serial_server_keeps_the_line_silence(transport: str, gap: float) -> None:
    """A Modbus TCP gateway frames the line itself; a transparent server forwards bytes
    as they come, so the bridge keeps t3.5 between frames."""
    scheduler = bus_scheduler(bus(transport=transport, serial_behind={"baudrate": 9600}))
    assert scheduler.gap == pytest.approx(gap)
    assert bus_scheduler(bus(transport=transport)).gap == 0.0


def test_one_bus_per_gateway_line() -> None:
    gateway = {"transport": "tcp", "host": "192.0.2.10", "serial_behind": {"baudrate": 9600}}
    data = {"buses": [{"id": "a"} | gateway, {"id": "b"} | gateway]}
    with pytest.raises(ConfigError, match=r"buses\.b\.host: 192\.0\.2\.10:502 is bus .a. too"):
        load_config_data(data, Path("gw.yaml"))
    other_port = {"id": "b"} | gateway | {"tcp_port": 4001}  # a second line of the gateway
    load_config_data({"buses": [{"id": "a"} | gateway, other_port]}, Path("gw.yaml"))
