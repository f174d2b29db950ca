"""The demo's ``demo/fault`` request: every malformed payload is answered, none raises."""

from __future__ import annotations

import asyncio
import json

import pytest

from bridge.cli.demo_control import fault_request
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import SimulatedUnit, Simulator


@pytest.mark.parametrize(
    "payload",
    [
        b'{"device": ["borehole_pump"]}',  # unhashable: was a TypeError out of the handler
        b'{"device": {"a": 1}}',
        b'{"device": 7}',
        b'{"device": "nowhere"}',
        b'{"device": "borehole_pump", "fault": 3}',
        b'{"device": "borehole_pump", "counter": "motor_life", "fault": "melt"}',
        b'{"device": "borehole_pump", "counter": "motor_life", "fault": null}',
        b'{"device": "borehole_pump", "counter": "operating_frequency", "fault": "zero"}',
        b'{"device": "borehole_pump", "counter": "nothing", "fault": "zero"}',
        b'{"device": "borehole_pump", "counter": ["motor_life"], "fault": "zero"}',
        b"[1, 2]",
        b"not json",
    ],
)
def test_a_malformed_fault_request_is_answered_with_an_error(payload: bytes) -> None:
    simulator = Simulator([SimulatedUnit(1, load_mapping(builtin_mapping_path("nastec_vasco")))])
    handle = fault_request({"borehole_pump": (simulator, 1)})
    answer = json.loads(asyncio.run(handle(payload)))
    assert answer["status"] == "error" and answer["error"]
    assert simulator.faults(1) == []


def test_a_counter_fault_request_makes_the_counter_misread() -> None:
    simulator = Simulator([SimulatedUnit(1, load_mapping(builtin_mapping_path("nastec_vasco")))])
    handle = fault_request({"borehole_pump": (simulator, 1)})
    payload = b'{"device": "borehole_pump", "counter": "motor_life", "fault": "reset"}'
    answer = json.loads(asyncio.run(handle(payload)))
    assert answer["status"] == "ok"
    assert simulator.value(1, "motor_life") == 0
