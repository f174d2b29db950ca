"""Issue 29's acceptance check: three masters share one serial line through the bridge.

The bridge polls two devices on one RTU line (a pty pair, the simulator at the far end)
and runs an MQTT command, while three masters use its Modbus TCP server at once: a
pymodbus client, libmodbus' ``mbpoll``, and Home Assistant's own ``modbus`` integration
(configured in YAML, pointed at the bridge's port, its sensors polling every second and
its ``modbus.write_register`` action writing). Every answer must equal the simulator's
registers, the line must see no CRC/framing error and no timeout, a guarded write must be
refused before the wire, and the devices must stay online and keep being polled.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from pathlib import Path

import pytest

from bridge.core.entity import Table
from tests.ha.homeassistant import HomeAssistant
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing
from tests.integration.test_gateway_masters import (
    MBPOLL,
    PUMP,
    STARTER,
    mbpoll,
    mbpoll_master,
    pymodbus_master,
    site,
    words,
)
from tests.ports import free_port

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(600)]
H = Table.HOLDING

MODBUS_YAML = """\
modbus:
  - name: bridge
    type: tcp
    host: 127.0.0.1
    port: {port}
    timeout: 5
    sensors:
      - name: Starter soft start time
        unique_id: gateway_starter_soft_start_time
        device_address: 3
        address: 4101
        input_type: holding
        scan_interval: 1
      - name: Starter soft stop time
        unique_id: gateway_starter_soft_stop_time
        device_address: 3
        address: 4102
        input_type: holding
        scan_interval: 1
      - name: Pump set value raw
        unique_id: gateway_pump_set_value_raw
        device_address: 1
        address: 51
        input_type: holding
        scan_interval: 1
"""


def state_of(states: list[dict[str, object]], entity_id: str) -> str | None:
    for state in states:
        if state["entity_id"] == entity_id:
            return str(state["state"])
    return None


async def ha_state(hass: HomeAssistant, entity_id: str) -> str | None:
    socket = await hass.websocket()
    try:
        return state_of(await socket.call("get_states"), entity_id)
    finally:
        await socket.close()


async def until_ha_reads(hass: HomeAssistant, entity_id: str, value: int) -> None:
    async with asyncio.timeout(60):
        while await ha_state(hass, entity_id) not in (str(value), f"{value}.0"):
            await asyncio.sleep(0.5)


@pytest.mark.skipif(MBPOLL is None, reason="mbpoll (libmodbus) is not installed")
async def test_three_masters_share_the_line_through_the_bridge(
    hass: HomeAssistant, ha_broker: Broker, tmp_path: Path
) -> None:
    port = free_port()
    async with (
        site(ha_broker, tmp_path, port, web=False) as s,
        observing(ha_broker, "modbus/starter") as observer,
    ):
        engine = s.bridge.engine
        hass.extra_yaml = MODBUS_YAML.format(port=port)
        hass.write_configuration()
        await asyncio.to_thread(hass.restart)  # the bridge polls on meanwhile
        polls_before = {d: p.health.requests for d, p in engine.devices.items()}

        # Home Assistant reads what the simulator holds, through the bridge
        await until_ha_reads(
            hass, "sensor.starter_soft_start_time", *words(s.sim, STARTER, 4101, 1)
        )
        await until_ha_reads(hass, "sensor.pump_set_value_raw", *words(s.sim, PUMP, 51, 1))

        # all three masters at once, and an MQTT command
        command = observer.client.publish("modbus/starter/set", json.dumps({"soft_stop_time": 14}))
        pymodbus_reads, mbpoll_reads, _ = await asyncio.gather(
            pymodbus_master(s, 10), mbpoll_master(s, 5), command
        )
        for answer, registers in pymodbus_reads + mbpoll_reads:
            assert answer in registers  # the device's registers at one moment of the read
        await until_ha_reads(hass, "sensor.starter_soft_stop_time", 14)

        # Home Assistant's own write action goes through the command checks
        socket = await hass.websocket()
        try:
            await socket.call(
                "call_service",
                domain="modbus",
                service="write_register",
                service_data={"hub": "bridge", "slave": STARTER, "address": 4101, "value": 33},
            )
            await eventually(lambda: s.sim.value(STARTER, "soft_start_time") == 33, 10)
            await until_ha_reads(hass, "sensor.starter_soft_start_time", 33)
            written = list(s.sim.writes)
            # rated_voltage is guarded (allow_dangerous_writes is off): never on the wire
            with contextlib.suppress(RuntimeError):  # Home Assistant may report the refusal
                await socket.call(
                    "call_service",
                    domain="modbus",
                    service="write_register",
                    service_data={"hub": "bridge", "slave": STARTER, "address": 4103, "value": 400},
                )
        finally:
            await socket.close()
        status, output = await mbpoll(port, STARTER, 4103, values=(400,))
        assert status != 0 and "Illegal function" in output, output
        await eventually(lambda: s.bridge.gateway.book.totals().refused >= 2, 10)
        assert s.sim.writes == written

        counters = engine.schedulers["line"].counters
        assert (counters.frame_errors, counters.timeouts) == (0, 0)
        for device_id, poller in engine.devices.items():
            assert poller.health.online, device_id
            assert poller.health.requests > polls_before[device_id], device_id
        assert s.bridge.gateway.book.totals().failed == 0
