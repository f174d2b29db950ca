"""Learnt refusals are not forever: the real engine against the simulator.

A device that refuses every read (an exception-02 storm: a unit rebooting, a gateway
answering everything with 02) is a device fault, not a map of holes: it goes offline,
is probed with backoff, nothing is learnt, and it is read again when it recovers. A device
that answers only busy goes offline too. A hole learnt from a real refusal is read again
after the re-check interval: answered, it is a register again; refused, it is learnt again
without a second warning.
"""

from __future__ import annotations

import logging
from typing import Any

import pytest

from bridge.core.entity import Table
from bridge.core.health import Fault, HealthPolicy
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.modbus.simulator import Quirks, Simulator
from tests.integration.harness import (
    Recorder,
    config,
    eventually,
    running,
    serving_tcp,
    simulator,
    tcp_bus,
)

H = Table.HOLDING
POLICY = HealthPolicy(offline_after=2, backoff_initial=0.2, backoff_max=0.4)
OUTPUT_POWER = 0x1005  # p2_vfd


def device(name: str, **fields: Any) -> dict[str, Any]:
    poll = {"poll": {"fast": 0.1, "slow": 0.5}}
    return {"id": name, "bus": "tcp", "unit": 1, "mapping": name} | poll | fields


def engine_for(port: int, name: str, recorder: Recorder, policy: HealthPolicy) -> Engine:
    return Engine(config([tcp_bus(port)], [device(name)]), recorder, policy=policy)


def holds_true_values(poller: DevicePoller, sim: Simulator) -> bool:
    readable = [k for k, p in poller.points.items() if p.entity.readable]
    return all(poller.values.get(k, "unread") == sim.value(1, k) for k in readable)


def availability(recorder: Recorder, name: str) -> list[bool | None]:
    """The device's online state as reported, changes only (not the "not known yet" of the
    updates before its first answer, e.g. the end of a first poll nobody answered)."""
    states: list[bool | None] = []
    for update in recorder.of(name):
        if update.online is not None and (not states or states[-1] != update.online):
            states.append(update.online)
    return states


def offline_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if getattr(r, "event", "") == "device_offline"]


@pytest.mark.asyncio
async def test_an_exception_2_storm_is_a_device_fault_and_nothing_is_learnt(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "bridge")
    sim, recorder = simulator((1, "soft_starter")), Recorder()
    async with serving_tcp(sim) as port:
        engine = engine_for(port, "soft_starter", recorder, POLICY)
        async with running(engine):
            starter = engine.devices["soft_starter"]
            await eventually(lambda: holds_true_values(starter, sim))

            sim.set_quirks(1, Quirks(exception_code=2))  # rebooting: every request 02
            await eventually(lambda: starter.health.online is False)
            refused = starter.health.exceptions[2]
            await eventually(lambda: starter.health.exceptions[2] >= refused + 3)  # probed
            await starter.read_now()  # a /get meanwhile learns nothing either
            assert starter.refused == frozenset()
            assert starter.health.fault is Fault.REFUSES

            sim.set_value(1, "phase_u_current", 42.0)
            sim.set_quirks(1, Quirks())
            await eventually(lambda: starter.health.online is True)
            await eventually(lambda: holds_true_values(starter, sim))
            assert starter.values["phase_u_current"] == 42.0
            assert starter.refused == frozenset()
            requests = starter.health.requests
            await eventually(lambda: starter.health.requests > requests + 10)  # polled again
    assert availability(recorder, "soft_starter")[-3:] == [True, False, True]
    assert any("refuses every read" in line for line in offline_lines(caplog))
    assert not [r for r in caplog.records if "not read again" in r.getMessage()]


@pytest.mark.asyncio
async def test_a_storm_keeps_the_holes_learnt_before_and_adds_none() -> None:
    hole = frozenset({OUTPUT_POWER})
    sim, recorder = simulator((1, "p2_vfd"), refused=hole), Recorder()
    async with serving_tcp(sim) as port:
        engine = engine_for(port, "p2_vfd", recorder, POLICY)
        async with running(engine):
            p2 = engine.devices["p2_vfd"]
            await eventually(lambda: p2.refused == {(H, OUTPUT_POWER)})
            await eventually(lambda: p2.values.get("output_current") is not None)

            sim.set_quirks(1, Quirks(exception_code=2, refused=hole))
            await eventually(lambda: p2.health.online is False)
            assert p2.refused == {(H, OUTPUT_POWER)}

            sim.set_value(1, "output_current", 125)
            sim.set_quirks(1, Quirks(refused=hole))
            await eventually(lambda: p2.values.get("output_current") == 125)
            assert p2.refused == {(H, OUTPUT_POWER)}
            assert p2.values["output_power"] is None
    assert availability(recorder, "p2_vfd") == [True, False, True]


@pytest.mark.asyncio
async def test_a_device_refusing_everything_from_the_start_is_offline_until_it_answers() -> None:
    sim, recorder = simulator((1, "soft_starter"), exception_code=2), Recorder()
    async with serving_tcp(sim) as port:
        engine = engine_for(port, "soft_starter", recorder, POLICY)
        async with running(engine):
            starter = engine.devices["soft_starter"]
            await eventually(lambda: starter.health.online is False)
            assert starter.refused == frozenset()
            assert all(value is None for value in starter.values.values())

            sim.set_quirks(1, Quirks())
            await eventually(lambda: starter.health.online is True)
            await eventually(lambda: holds_true_values(starter, sim))
            assert starter.refused == frozenset()
    assert availability(recorder, "soft_starter") == [False, True]


@pytest.mark.asyncio
async def test_a_device_answering_only_busy_goes_offline_and_comes_back(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "bridge")
    sim, recorder = simulator((1, "soft_starter")), Recorder()
    policy = HealthPolicy(offline_after=2, backoff_initial=0.2, backoff_max=0.4,
                          busy_offline_after=0.5)  # fmt: skip
    async with serving_tcp(sim) as port:
        engine = engine_for(port, "soft_starter", recorder, policy)
        async with running(engine):
            starter = engine.devices["soft_starter"]
            await eventually(lambda: holds_true_values(starter, sim))

            sim.set_quirks(1, Quirks(exception_code=6))  # busy, and busy, and busy
            await eventually(lambda: starter.health.online is False)
            assert starter.health.fault is Fault.BUSY
            busy = starter.health.busy
            await eventually(lambda: starter.health.busy >= busy + 2)  # probed, still busy
            assert starter.health.online is False

            sim.set_value(1, "phase_u_current", 42.0)
            sim.set_quirks(1, Quirks())
            await eventually(lambda: starter.health.online is True)
            await eventually(lambda: starter.values["phase_u_current"] == 42.0)
    assert availability(recorder, "soft_starter")[-3:] == [True, False, True]
    assert any("answers only 'busy'" in line for line in offline_lines(caplog))


@pytest.mark.asyncio
async def test_a_learnt_refusal_is_read_again_after_the_recheck_interval(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "bridge")
    sim, recorder = simulator((1, "p2_vfd"), refused=frozenset({OUTPUT_POWER})), Recorder()
    policy = HealthPolicy(offline_after=2, backoff_initial=0.2, refusal_recheck=0.3)
    async with serving_tcp(sim) as port:
        engine = engine_for(port, "p2_vfd", recorder, policy)
        async with running(engine):
            p2 = engine.devices["p2_vfd"]
            await eventually(lambda: (H, OUTPUT_POWER) in p2.refused)
            assert p2.values["output_power"] is None
            refused = p2.health.exceptions[2]
            await eventually(lambda: p2.health.exceptions[2] >= refused + 3)  # re-read, refused
            assert p2.health.online is True

            sim.set_quirks(1, Quirks())  # the option board is fitted now
            await eventually(lambda: p2.values["output_power"] == sim.value(1, "output_power"))
            assert (H, OUTPUT_POWER) not in p2.refused
            assert p2.health.online is True
            assert availability(recorder, "p2_vfd") == [True]
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    said = f"holding 0x1005 (wire {OUTPUT_POWER})"  # as the manual prints it, and as sent
    refused = f"p2_vfd refused {said} with exception 2 (illegal data address); not read again"
    assert len([w for w in warnings if w.startswith(refused)]) == 1
    assert any(f"answers {said} again" in r.getMessage() for r in caplog.records)
