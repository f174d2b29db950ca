"""Alarms without hardware: the simulator over Modbus follows the bridge's commands, trips
on demand (``raise_fault``, ``simulate --fault``) and clears on the device's own reset."""

from __future__ import annotations

import argparse

import pytest

from bridge.cli.console import _parser
from bridge.cli.simulate import build_simulator
from bridge.core.state import active_alarms
from bridge.errors import InputError
from bridge.modbus.engine import Engine
from tests.integration.harness import config, eventually, running, serving_tcp, simulator, tcp_bus


def simulate_args(*args: str) -> argparse.Namespace:
    return _parser().parse_args(["simulate", "--tcp", "127.0.0.1:0", *args])


@pytest.mark.asyncio
async def test_the_bridge_stops_trips_and_resets_a_simulated_drive() -> None:
    sim = simulator((1, "p2_vfd"))
    async with serving_tcp(sim) as port:
        device = {"id": "fan", "bus": "tcp", "unit": 1, "mapping": "p2_vfd"}
        engine = Engine(config([tcp_bus(port)], [device | {"poll": {"fast": 0.1}}]))
        async with running(engine):
            fan = engine.devices["fan"]
            await eventually(lambda: fan.values.get("status") == "running_forward")

            await fan.write("stop", "PRESS")
            await eventually(lambda: fan.values.get("status") == "standby")
            assert fan.values["running"] is False
            await eventually(lambda: fan.values.get("output_current") == 0)

            await fan.write("command", "forward_run")
            await eventually(lambda: fan.values.get("status") == "running_forward")

            sim.raise_fault(1, "fault_code", "module_overheat")
            await eventually(lambda: active_alarms(fan.points, fan.values) == ["module_overheat"])
            assert fan.values["status"] == "fault"

            await fan.write("fault_reset", "PRESS")
            await eventually(lambda: active_alarms(fan.points, fan.values) == [])
            assert fan.values["status"] == "standby"  # a new run command is needed


@pytest.mark.asyncio
async def test_a_stopped_machine_stays_still_while_the_rest_moves() -> None:
    sim = simulator((1, "p2_vfd"), tick=0.02)
    async with serving_tcp(sim):
        sim.raise_fault(1, "fault_code")  # tripped: stopped
        first = sim.value(1, "dc_bus_voltage")
        await eventually(lambda: sim.value(1, "dc_bus_voltage") != first)  # ticks go on
        assert (sim.value(1, "output_current"), sim.value(1, "running_speed")) == (0, 0)


def test_simulate_fault_starts_the_device_tripped() -> None:
    sim = build_simulator(
        simulate_args(
            "--mapping", "nastec_vasco", "--unit", "1",
            "--mapping", "soft_starter", "--unit", "2",
            "--fault", "alarm_dry_running", "--fault", "fault_status=overload",
        )
    )  # fmt: skip
    assert sim.faults(1) == ["alarm_dry_running"]
    assert sim.value(1, "status") == "alarm"
    assert sim.faults(2) == ["fault_status"]
    assert sim.value(2, "fault_status") == "overload"


@pytest.mark.parametrize(
    ("fault", "message"),
    [
        ("nothing", "--fault nothing: no simulated unit has it (alarms: ['alarm_address_error'"),
        ("alarm_cpu=hot", "--fault alarm_cpu=hot: alarm_cpu is a yes/no alarm: give no label"),
    ],
)
def test_simulate_refuses_a_fault_the_devices_do_not_have(fault: str, message: str) -> None:
    with pytest.raises(InputError) as refused:
        build_simulator(simulate_args("--mapping", "nastec_vasco", "--unit", "1", "--fault", fault))
    assert refused.value.issues[0].startswith(message)


@pytest.mark.asyncio
async def test_simulate_counter_fault_happens_when_it_is_due() -> None:
    sim = build_simulator(
        simulate_args(
            "--mapping", "smartgen_hgm6100", "--unit", "1", "--tick", "0",
            "--counter-fault", "energy=reset@0.2", "--counter-fault", "run_hours=wrap@0.2",
        )
    )  # fmt: skip
    before = sim.value(1, "energy")
    assert isinstance(before, int) and before > 0
    async with serving_tcp(sim):
        await eventually(lambda: sim.value(1, "energy") == 0)
        assert sim.value(1, "run_hours") == 65536 * 10000 - 2


@pytest.mark.parametrize(
    ("fault", "message"),
    [
        ("nothing=zero", "--counter-fault nothing=zero: no simulated unit has 'nothing'"),
        ("energy=melt", "--counter-fault energy=melt: counter fault 'melt': one of zero, "),
        ("energy=zero@soon", "--counter-fault energy=zero@soon: SECONDS must be a number"),
        ("oil_pressure=zero", "--counter-fault oil_pressure=zero: oil_pressure is not a counter"),
    ],
)
def test_simulate_refuses_a_counter_fault_it_cannot_make(fault: str, message: str) -> None:
    with pytest.raises(InputError) as refused:
        build_simulator(
            simulate_args("--mapping", "smartgen_hgm6100", "--unit", "1", "--counter-fault", fault)
        )
    assert refused.value.issues[0].startswith(message), refused.value.issues
