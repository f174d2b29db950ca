"""The demo's own request: trip a simulated device, so alarm automations can be tried.

``<base>/bridge/request/demo/fault`` with ``{"device": "borehole_pump", "fault":
"alarm_dry_running"}`` raises that alarm in the simulated device (``"fault_code=motor_overload"``
picks a fault code's label); ``{"device": ..., "fault": null}`` clears every fault, as if
the cause went away (the device's own fault reset, where it has one, clears them too).
``{"device": "genset", "counter": "energy", "fault": "tear"}`` makes a counter misread
instead (zero, reboot, tear, jitter, wrap, reset: bridge/core/simulation_counter.py), to
watch the bridge hold it back.
The answer on ``<base>/bridge/response/demo/fault`` lists the device's active alarms.
Only the demo serves it: a bridge on real hardware has no such request.
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable
from typing import Any

from bridge.core.management_request import response
from bridge.errors import ValueRejectedError
from bridge.modbus.simulator import Simulator

FAULT_REQUEST = "demo/fault"


def fault_request(
    units: dict[str, tuple[Simulator, int]],
) -> Callable[[bytes], Awaitable[str]]:
    """The handler of ``demo/fault`` for the devices ``units`` names (device id -> the
    simulator serving it and its unit)."""

    async def handle(payload: bytes) -> str:
        transaction: Any = None
        try:
            data = json.loads(payload or b"{}")
            if not isinstance(data, dict):
                raise ValueRejectedError("give a JSON object: {device, fault}")
            transaction = data.get("transaction")
            device = data.get("device")
            if not isinstance(device, str) or device not in units:
                raise ValueRejectedError(f"device: one of {sorted(units)}, not {device!r:.60}")
            fault = data.get("fault")
            counter = data.get("counter")
            simulator, unit = units[device]
            if counter is not None:
                if not isinstance(counter, str) or not isinstance(fault, str):
                    raise ValueRejectedError("counter: a counter key, with fault: its fault")
                simulator.counter_fault(unit, counter, fault)
            elif fault is None:
                simulator.clear_faults(unit)
            elif isinstance(fault, str):
                key, _, label = fault.partition("=")
                simulator.raise_fault(unit, key, label or None)
            else:
                raise ValueRejectedError("fault: an alarm key (KEY or KEY=LABEL), or null")
        except ValueError as exc:  # JSON and refusals (ValueRejectedError is no ValueError)
            return response(error=f"payload: {exc}", transaction=transaction)
        except (ValueRejectedError, KeyError) as exc:  # KeyError: a key the unit lacks
            return response(error=str(exc).strip('"'), transaction=transaction)
        simulator, unit = units[device]
        faults = simulator.faults(unit)
        return response({"device": device, "faults": faults}, transaction=transaction)

    return handle
