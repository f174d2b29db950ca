"""The soak's faults, thrown: one coroutine per kind of bench/soak_schedule.py.

Faults overlap as the schedule says, except those on the broker, which take turns (a
broker is not killed while it is stopped). Command bursts wait for the broker to be up:
a command published to a dead broker is lost by the broker, which says nothing of the
bridge. Each burst mixes live commands, retained ones (must never run), ones with a short
MQTT 5 message expiry (must not run late; under a burst some miss it and must be dropped),
two-key JSON ``/set``s and tries at guarded registers (must never reach the wire).
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import os
import random
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException
from soak_invariants import Sent
from soak_schedule import Fault
from soak_site import (
    BASE,
    COMMAND_DEVICE,
    COMMAND_EXPIRY,
    COMMAND_KEYS,
    COUNTER_FAULT_KEYS,
    GATEWAY_UNITS,
    mappings,
)

from bridge.core.codec import encode
from bridge.core.entity import PollClass, Table
from bridge.core.simulation import Quirks

if TYPE_CHECKING:
    from soak_faults import Soak
    from soak_observer import Publisher

SHORT_EXPIRY = 1  # s: the MQTT 5 message expiry of the commands that may expire


class Thrower:
    def __init__(
        self, soak: Soak, publisher: Publisher, config: Callable[[bool], Path], gateway_port: int
    ) -> None:
        self.soak, self.publisher, self.config, self.gateway_port = (
            soak,
            publisher,
            config,
            gateway_port,
        )
        self.records = soak.records
        self.bridge_pid = 0
        self.broker_turn = asyncio.Lock()
        self.words = itertools.count(1000)  # every command writes a word of its own
        self.idents = itertools.count(1)
        self.transactions = itertools.count(1)
        loaded = mappings()
        self.points = loaded[COMMAND_DEVICE].points()
        self.guarded_tries = [
            (device, key, _harmless_value(point))
            for device in ("vacon", "pump")
            for key, point in loaded[device].points().items()
            if point.entity.dangerous and point.entity.writable
        ][::7]
        unit = self.records.facts.unit[COMMAND_DEVICE]
        for key in COMMAND_KEYS:
            self.records.command_registers[(unit, self.points[key].write_address)] = (
                COMMAND_DEVICE,
                key,
            )
        self.gateway_reads = {
            unit: _first_fast(loaded[device]) for unit, device in GATEWAY_UNITS.items()
        }

    async def throw_all(self, schedule: tuple[Fault, ...], started: float) -> None:
        async with asyncio.TaskGroup() as group:
            for fault in schedule:
                await asyncio.sleep(max(0.0, started + fault.at - time.monotonic()))
                group.create_task(self.throw(fault))

    async def throw(self, fault: Fault) -> None:
        self.records.counts[f"thrown {fault.kind}"] += 1
        print(
            f"[{fault.position}] t+{fault.at:.0f} s {fault.kind} {fault.target} {fault.hold:g} s",
            flush=True,
        )
        await getattr(self, fault.kind)(fault, random.Random(fault.seed))  # noqa: S311

    # --- the broker -----------------------------------------------------------------------

    async def broker_restart(self, fault: Fault, _: random.Random) -> None:
        async with self.broker_turn:
            outage = [time.monotonic(), math.inf]
            self.records.held_up.append(outage)
            await asyncio.to_thread(self.soak.broker.stop)
            await asyncio.sleep(fault.hold)
            await asyncio.to_thread(self.soak.broker.start)
            outage[1] = time.monotonic()

    async def broker_stall(self, fault: Fault, _: random.Random) -> None:
        async with self.broker_turn:
            pid = self.soak.broker.process.pid  # type: ignore[union-attr]
            stall = [time.monotonic(), math.inf]
            self.records.held_up.append(stall)
            os.kill(pid, signal.SIGSTOP)
            try:
                await asyncio.sleep(fault.hold)
            finally:
                os.kill(pid, signal.SIGCONT)
                stall[1] = time.monotonic()

    # --- devices and the line ---------------------------------------------------------------

    async def device_reboot(self, fault: Fault, rng: random.Random) -> None:
        unit = self.records.facts.unit[fault.target]
        kind = rng.choice(("reboot", "zero"))
        self._simulator(fault.target).counter_fault(unit, COUNTER_FAULT_KEYS[fault.target], kind)

    async def counter_reset(self, fault: Fault, _: random.Random) -> None:
        unit = self.records.facts.unit[fault.target]
        self._simulator(fault.target).counter_fault(unit, COUNTER_FAULT_KEYS[fault.target], "reset")

    async def device_silent(self, fault: Fault, _: random.Random) -> None:
        unit, simulator = self.records.facts.unit[fault.target], self._simulator(fault.target)
        silence = self.records.silent(fault.target, time.monotonic())
        simulator.set_quirks(unit, Quirks(dead=True))
        try:
            await asyncio.sleep(fault.hold)
        finally:
            simulator.set_quirks(unit, Quirks())
            silence[2] = time.monotonic()

    async def line_noise(self, fault: Fault, _: random.Random) -> None:
        await self._line("noise", fault.hold)

    async def torn_frames(self, fault: Fault, _: random.Random) -> None:
        await self._line("torn", fault.hold)

    async def _line(self, mode: str, hold: float) -> None:
        self.records.line.mode = mode
        try:
            await asyncio.sleep(hold)
        finally:
            self.records.line.mode = "clean"

    # --- the bridge's configuration -----------------------------------------------------------

    async def config_reload(self, _: Fault, rng: random.Random) -> None:
        slower = rng.random() < 0.5
        self.config(slower)
        self.records.counts[f"config rewritten ({'slower polls' if slower else 'the same'})"] += 1
        if self.bridge_pid:
            os.kill(self.bridge_pid, signal.SIGHUP)
            self.records.counts["SIGHUP sent"] += 1

    async def mapping_reload(self, _: Fault, __: random.Random) -> None:
        await self._broker_up()
        payload = json.dumps({"transaction": next(self.transactions)})
        self.publisher.publish(f"{BASE}/bridge/request/mapping/reload", payload)
        self.records.counts["mapping reloads requested"] += 1

    async def ha_online(self, _: Fault, __: random.Random) -> None:
        await self._broker_up()
        self.publisher.publish("homeassistant/status", "online")

    # --- masters and commands -----------------------------------------------------------------

    async def gateway_masters(self, fault: Fault, rng: random.Random) -> None:
        async with asyncio.TaskGroup() as group:
            for _ in range(rng.randint(1, 3)):
                group.create_task(self._master(fault.hold, rng.choice(list(GATEWAY_UNITS))))

    async def _master(self, hold: float, unit: int) -> None:
        client = AsyncModbusTcpClient("127.0.0.1", port=self.gateway_port, timeout=2, retries=0)
        counts = self.records.counts
        counts["gateway masters connected"] += 0
        try:
            if not await client.connect():
                counts["gateway masters refused a connection"] += 1
                return
            counts["gateway masters connected"] += 1
            table, address = self.gateway_reads[unit]
            read = (
                client.read_input_registers
                if table is Table.INPUT
                else client.read_holding_registers
            )
            end = time.monotonic() + hold
            while time.monotonic() < end:
                try:
                    answer = await read(address, count=1, device_id=unit)
                except (ModbusException, OSError, TimeoutError):
                    counts["gateway reads failed (no answer)"] += 1
                    await asyncio.sleep(0.1)
                    continue
                code = getattr(answer, "exception_code", 0) if answer.isError() else 0
                counts[f"gateway reads answered {'ok' if code == 0 else f'exception {code}'}"] += 1
        finally:
            client.close()  # vanishes: no goodbye beyond the socket closing

    async def command_burst(self, _: Fault, rng: random.Random) -> None:
        await self._broker_up()
        for _ in range(rng.randint(5, 20)):
            draw = rng.random()
            if draw < 0.08 and self.guarded_tries:
                device, key, value = rng.choice(self.guarded_tries)
                self.publisher.publish(f"{BASE}/{device}/{key}/set", value)
                self.records.counts["commands sent: guarded tries"] += 1
            elif draw < 0.2:
                self._send([rng.choice(COMMAND_KEYS)], retained=True, expiry=None)
            elif draw < 0.45:
                self._send([rng.choice(COMMAND_KEYS)], retained=False, expiry=SHORT_EXPIRY)
            elif draw < 0.55:
                self._send(rng.sample(COMMAND_KEYS, 2), retained=False, expiry=None)
            else:
                self._send([rng.choice(COMMAND_KEYS)], retained=False, expiry=None)
            await asyncio.sleep(rng.uniform(0, 0.05))

    def _send(self, keys: list[str], *, retained: bool, expiry: int | None) -> None:
        values = {key: next(self.words) for key in keys}
        if len(keys) == 1:
            topic, payload = f"{BASE}/{COMMAND_DEVICE}/{keys[0]}/set", str(values[keys[0]])
        else:
            topic, payload = f"{BASE}/{COMMAND_DEVICE}/set", json.dumps(values)
        now = time.monotonic()
        lifetime = COMMAND_EXPIRY if expiry is None else min(COMMAND_EXPIRY, expiry)
        for key, value in values.items():
            write = encode(self.points[key], value, {})[0]
            unit = self.records.facts.unit[COMMAND_DEVICE]
            sent = Sent(
                next(self.idents),
                now,
                COMMAND_DEVICE,
                unit,
                write.address,
                write.values[0],
                retained,
                lifetime,
            )
            self.records.command(sent, topic, payload.encode())
        kind = (
            "retained"
            if retained
            else "short expiry"
            if expiry is not None
            else "two-key /set"
            if len(keys) > 1
            else "live"
        )
        self.records.counts[f"commands sent: {kind}"] += 1
        self.publisher.publish(topic, payload, retain=retained, expiry=expiry)

    async def _broker_up(self) -> None:
        async with self.broker_turn:
            pass
        while not self.publisher.connected:
            await asyncio.sleep(0.2)

    def _simulator(self, device: str):
        return self.soak.simulators["tcp" if device == "pump" else "rs485"]


def _harmless_value(point: object) -> str:
    entity = point.entity  # type: ignore[attr-defined]
    if entity.min is not None and entity.max is not None:
        return f"{(entity.min + entity.max) / 2:g}"
    return "ON"


def _first_fast(mapping: object) -> tuple[Table, int]:
    point = next(p for p in mapping.points().values() if p.entity.poll_class is PollClass.FAST)  # type: ignore[attr-defined]
    return point.entity.table, point.address
