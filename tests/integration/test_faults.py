"""Fault injection: the real bridge (or engine), the simulator and Mosquitto under trouble.

Each test breaks one thing while the others keep working: a unit that dies, one that
answers slowly or too late, one that answers every request with an exception, a noisy
RS-485 line (garbage and bad CRCs), a serial port or TCP gateway that vanishes and comes
back, a broker that is killed. Across all of them: the bridge task is still running at
the end, no value the devices do not hold is ever published, and every command is either
written exactly once or refused with a message on ``<base>/<device>/error``, never
written late. Waits are bounded (``eventually``); nothing asserts on wall-clock time.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import random
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import LoadedConfig, load_config_data
from bridge.core.health import DeviceHealth
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.errors import BusError
from bridge.modbus.engine import Engine
from bridge.modbus.null_modem import Send, null_modem
from bridge.modbus.scheduler import REOPEN_INITIAL, BusScheduler
from bridge.modbus.simulator import Quirks, Simulator
from tests.integration.harness import (
    FAST_POLICY,
    Recorder,
    cancel,
    config,
    eventually,
    serving_tcp,
    simulator,
    tcp_bus,
)
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing

PUMP, STARTER, DRIVE, P2 = 1, 2, 3, 4
MAPPINGS = {PUMP: "nastec_vasco", STARTER: "soft_starter", DRIVE: "vacon_nx", P2: "p2_vfd"}
NAMES = {PUMP: "pump", STARTER: "starter", DRIVE: "drive", P2: "p2"}
MOVING = {PUMP: "dc_bus_voltage", STARTER: "phase_u_current", DRIVE: "motor_speed"}
THREE = (PUMP, STARTER, DRIVE)  # the pump's mapping reads in 113 blocks, the others in <= 10
FAST_POLL = {"poll": {"fast": 0.1, "slow": 1}}


# --- running the bridge -----------------------------------------------------------------


def units_of(*units: int) -> Simulator:
    """The simulator with these units, values still (tick 0)."""
    return simulator(*((unit, MAPPINGS[unit]) for unit in units))


def device(unit: int, bus: str = "tcp", **fields: Any) -> dict[str, Any]:
    return (
        {"id": NAMES[unit], "bus": bus, "unit": unit, "mapping": MAPPINGS[unit]}
        | FAST_POLL
        | fields
    )


def bridge_config(
    broker: Broker, buses: list[dict[str, Any]], devices: list[dict[str, Any]], **mqtt: Any
) -> LoadedConfig:
    data = {
        "mqtt": {"url": broker.url, "base_topic": "modbus", "command_expiry": 3} | mqtt,
        "bridge": {"health_interval": 0},
        "buses": buses,
        "devices": devices,
    }
    return load_config_data(data, Path("faults.yaml"))


@contextlib.asynccontextmanager
async def running_bridge(loaded: LoadedConfig) -> AsyncIterator[Bridge]:
    """Run a Bridge whose devices go offline after 2 failures and are probed every
    0.2-0.4 s; fail if the bridge task ended by itself."""
    bridge = Bridge(loaded)
    for poller in bridge.engine.devices.values():
        poller.link.health = DeviceHealth(FAST_POLICY)
    task = asyncio.create_task(bridge.run(), name="bridge")
    try:
        yield bridge
        if task.done():
            raise AssertionError("the bridge stopped") from task.exception()
    finally:
        await cancel(task)


def availability(observer: Observer, unit: int, since: int = 0) -> list[bytes]:
    return [m.payload for m in observer.after(since, f"modbus/{NAMES[unit]}/availability")]


def online(observer: Observer, *units: int) -> bool:
    return all(observer.retained.get(f"modbus/{NAMES[u]}/availability") == b"online" for u in units)


def errors(observer: Observer, unit: int, since: int = 0) -> list[dict[str, Any]]:
    return [json.loads(m.payload) for m in observer.after(since, f"modbus/{NAMES[unit]}/error")]


def published(observer: Observer, unit: int) -> Iterator[dict[str, Any]]:
    for message in observer.log:
        if message.topic == f"modbus/{NAMES[unit]}":
            yield json.loads(message.payload)


def assert_true_values(
    documents: Iterator[dict[str, Any]],
    sim: Simulator,
    unit: int,
    also: dict[str, set[object]] | None = None,
) -> None:
    """Every value published for ``unit`` is one the simulated device held (``also``: the
    values a key held before the test changed it)."""
    status = load_mapping(builtin_mapping_path(MAPPINGS[unit])).status
    count = 0
    for document in documents:
        for key, value in document.items():
            if key in ("alarms", "last_reset") or value is None:
                continue  # not register values: the active alarms, when counts began
            held = sim.value(unit, status if key == "status" and status else key)
            assert value == held or value in (also or {}).get(key, set()), (
                f"unit {unit}: {key} published as {value!r}, the device holds {held!r}"
            )
            count += 1
    assert count, f"nothing was published for unit {unit}"


def writes_to(sim: Simulator, unit: int, address: int, value: int) -> int:
    """How often ``value`` was written to ``address`` of ``unit``."""
    return sum(
        1 for u, w in sim.writes if u == unit and w.address == address and w.values == (value,)
    )


PD_IN_1 = 2003  # vacon_nx pd_in_1: a plain s16 register, no EEPROM, no guard


# --- a dead unit, a slow unit, a unit that answers too late ------------------------------


@pytest.mark.asyncio
async def test_a_dead_unit_goes_offline_once_and_is_probed_with_backoff(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch
) -> None:
    sim = units_of(PUMP, STARTER, DRIVE)
    async with serving_tcp(sim) as port, observing(mosquitto, "modbus/#") as observer:
        buses = [tcp_bus(port, timeout=0.2)]
        loaded = bridge_config(mosquitto, buses, [device(u) for u in THREE])
        async with running_bridge(loaded) as bridge:
            await eventually(lambda: online(observer, *THREE), timeout=20)
            drive = bridge.engine.devices["drive"]
            probes = watch_requests(bridge.engine.schedulers["tcp"], drive, monkeypatch)
            seen = len(observer.log)

            sim.set_quirks(DRIVE, Quirks(dead=True))
            await eventually(lambda: drive.health.online is False)
            first_probe = len(probes)
            live = {name: bridge.engine.devices[name] for name in ("pump", "starter")}
            requests = {name: p.health.requests for name, p in live.items()}
            await eventually(lambda: len(probes) >= first_probe + 4, timeout=10)
            for at, state, next_attempt in probes[first_probe:]:
                assert state is False
                assert at >= next_attempt, "an offline unit is probed only when its backoff ran out"
            assert drive.health.backoff == FAST_POLICY.backoff_max  # doubled up to the cap
            await eventually(
                lambda: all(p.health.requests > requests[n] + 5 for n, p in live.items())
            )
            assert all(p.health.online and p.health.errors == 0 for p in live.values())
            assert availability(observer, DRIVE, seen) == [b"offline"]  # once, not per probe

            sim.set_quirks(DRIVE, Quirks())
            await eventually(lambda: online(observer, DRIVE), timeout=10)
            assert availability(observer, DRIVE, seen) == [b"offline", b"online"]
            assert availability(observer, PUMP, seen) == availability(observer, STARTER, seen) == []
            await observer.client.publish("modbus/drive/pd_in_1/set", "321")
            await eventually(lambda: writes_to(sim, DRIVE, PD_IN_1, 321) == 1)
    for unit in (PUMP, STARTER):
        assert_true_values(published(observer, unit), sim, unit)


def watch_requests(
    scheduler: BusScheduler, poller: Any, monkeypatch: pytest.MonkeyPatch
) -> list[tuple[float, bool | None, float]]:
    """Record (when, online, next_attempt) of every request ``poller`` submits."""
    seen: list[tuple[float, bool | None, float]] = []
    submit = scheduler.submit

    async def watched(unit: int, request: Any, **options: Any) -> tuple[int, ...]:
        if unit == poller.device.unit:
            health = poller.health
            seen.append((time.monotonic(), health.online, health.next_attempt))
        return await submit(unit, request, **options)

    monkeypatch.setattr(scheduler, "submit", watched)
    return seen


@pytest.mark.asyncio
async def test_a_slow_unit_beside_fast_ones() -> None:
    """A unit answering after 60 % of the timeout stays online, and the others poll on."""
    units = (STARTER, DRIVE, P2)
    sim = units_of(*units)
    sim.set_quirks(DRIVE, Quirks(latency=0.6))
    recorder = Recorder()
    async with serving_tcp(sim) as port:
        loaded = config([tcp_bus(port, timeout=1.0)], [device(u) for u in units])
        engine = Engine(loaded, recorder, policy=FAST_POLICY)
        task = asyncio.create_task(engine.run())
        try:
            slow = engine.devices["drive"]
            fast = [engine.devices["starter"], engine.devices["p2"]]
            await eventually(lambda: all(p.values for p in (slow, *fast)), timeout=30)
            requests = [p.health.requests for p in fast]
            slow_requests = slow.health.requests
            await eventually(lambda: slow.health.requests >= slow_requests + 3, timeout=20)
            assert all(p.health.requests > r for p, r in zip(fast, requests, strict=True))
            assert await engine.write("drive", "pd_in_1", 77) == 77
            assert writes_to(sim, DRIVE, PD_IN_1, 77) == 1
            assert not task.done()
        finally:
            await cancel(task)
    assert slow.health.online is True
    assert all(u.online is not False for u in recorder.updates), "nobody went offline"
    assert all(p.health.errors == 0 for p in fast)
    for unit in units:
        updates = [u.values for u in recorder.of(NAMES[unit])]
        assert_true_values(iter(updates), sim, unit, also={"pd_in_1": {0}})


@contextlib.asynccontextmanager
async def serving_line(sim: Simulator, cable: Any) -> AsyncIterator[str]:
    """Serve ``sim`` on the device end of ``cable``; yield the bridge end's path."""
    with cable as (device_end, bridge_end):
        task = asyncio.create_task(sim.serve_serial(device_end, baudrate=115200))
        try:
            await asyncio.wait_for(sim.ready.wait(), 5)
            yield bridge_end
        finally:
            await cancel(task)


def rtu_bus(port: str, **fields: Any) -> dict[str, Any]:
    return {
        "id": "rs485",
        "transport": "rtu",
        "port": port,
        "baudrate": 115200,
        "timeout": 0.3,
        "retries": 0,
    } | fields


@pytest.mark.asyncio
async def test_late_replies_on_an_rtu_line_are_never_taken_for_the_next_request() -> None:
    """RTU replies carry no transaction id: a reply that comes after the timeout must not
    be read as the answer to the unit's next request (another block's registers)."""
    sim = units_of(PUMP, STARTER)
    sim.set_quirks(PUMP, Quirks(latency=0.35))  # just after the 0.3 s timeout
    recorder = Recorder()
    async with serving_line(sim, null_modem()) as path:
        steady = {"protocol": {"response_timeout": 1.0}}  # the other unit: no timeouts
        poll = {"poll": {"fast": 0.05, "slow": 0.5}}
        devices = [device(PUMP, "rs485", **poll), device(STARTER, "rs485", **poll, **steady)]
        engine = Engine(config([rtu_bus(path)], devices), recorder, policy=FAST_POLICY)
        task = asyncio.create_task(engine.run())
        try:
            late, steady_unit = engine.devices["pump"], engine.devices["starter"]
            await eventually(lambda: late.health.timeouts >= 6, timeout=20)
            assert late.health.online is False
            sim.set_quirks(PUMP, Quirks())
            await eventually(lambda: late.health.online is True, timeout=10)
            await eventually(lambda: "status" in late.values)
            assert not task.done()
        finally:
            await cancel(task)
    for unit, name in ((PUMP, "pump"), (STARTER, "starter")):
        assert_true_values(iter(u.values for u in recorder.of(name)), sim, unit)
    assert steady_unit.health.errors == 0


# --- exception storms ----------------------------------------------------------------------


@pytest.mark.asyncio
async def test_an_exception_storm_moves_counters_and_spares_the_other_units(
    mosquitto: Broker,
) -> None:
    """The drive answers everything with 06 (busy), the pump with 04 (device failure)."""
    sim = units_of(PUMP, STARTER, DRIVE)
    async with serving_tcp(sim) as port, observing(mosquitto, "modbus/#") as observer:
        buses = [tcp_bus(port, timeout=0.3)]
        loaded = bridge_config(mosquitto, buses, [device(u) for u in THREE])
        async with running_bridge(loaded) as bridge:
            await eventually(lambda: online(observer, *THREE), timeout=20)
            pump, starter, drive = (bridge.engine.devices[n] for n in ("pump", "starter", "drive"))
            bus = bridge.engine.schedulers["tcp"].counters
            seen, exceptions, requests = len(observer.log), bus.exceptions, starter.health.requests

            sim.set_quirks(DRIVE, Quirks(exception_code=6))
            sim.set_quirks(PUMP, Quirks(exception_code=4))
            await eventually(lambda: drive.health.exceptions[6] >= 5 and drive.health.busy >= 5)
            await eventually(lambda: pump.health.online is False and pump.health.exceptions[4] >= 2)
            assert bus.exceptions >= exceptions + 7
            assert drive.health.online is True  # busy: alive
            await observer.client.publish("modbus/drive/pd_in_1/set", "606")
            await observer.client.publish("modbus/pump/start_stop/set", "ON")
            await eventually(lambda: errors(observer, DRIVE, seen) and errors(observer, PUMP, seen))
            assert "busy" in errors(observer, DRIVE, seen)[0]["error"]
            assert "offline" in errors(observer, PUMP, seen)[0]["error"]
            assert writes_to(sim, DRIVE, PD_IN_1, 606) == 1  # refused once, never resent
            assert starter.health.online is True
            assert starter.health.errors == 0
            await eventually(lambda: starter.health.requests > requests + 10)

            sim.set_quirks(DRIVE, Quirks())
            sim.set_quirks(PUMP, Quirks())
            await eventually(lambda: online(observer, PUMP), timeout=10)
            assert availability(observer, PUMP, seen) == [b"offline", b"online"]
            assert availability(observer, DRIVE, seen) == []
            await observer.client.publish("modbus/drive/pd_in_1/set", "607")
            await eventually(lambda: observer.json("modbus/drive").get("pd_in_1") == 607)
            assert writes_to(sim, DRIVE, PD_IN_1, 607) == 1
            assert len(errors(observer, DRIVE, seen)) == len(errors(observer, PUMP, seen)) == 1
    assert_true_values(published(observer, PUMP), sim, PUMP)
    assert_true_values(published(observer, STARTER), sim, STARTER)
    assert_true_values(published(observer, DRIVE), sim, DRIVE, also={"pd_in_1": {0}})


# --- a noisy line ----------------------------------------------------------------------------


class NoisyCable:
    """A null modem (like ``bridge.modbus.null_modem``) whose device-to-bridge direction
    can flip a byte of every n-th reply (a wrong CRC) and add garbage before and after
    replies. Garbage bytes are 0x80-0xFF: a frame read from an offset inside the garbage
    names unit 128-255, so even one whose CRC happened to match answers nobody here."""

    def __init__(self, seed: int = 7) -> None:
        self.rng = random.Random(seed)
        self.corrupt_every = 0
        self.garbage = False
        self.replies = self.corrupted = self.junk = 0

    def noise(self, on: bool) -> None:
        self.corrupt_every, self.garbage = (3, True) if on else (0, False)

    def _garbage(self) -> bytes:
        self.junk += 1
        return bytes(self.rng.randrange(0x80, 0x100) for _ in range(self.rng.randrange(1, 6)))

    def open(self) -> contextlib.AbstractContextManager[tuple[str, str]]:
        """``(device_end, bridge_end)``: ``null_modem()`` with this noise on the replies."""
        return null_modem(self._damage)

    def _damage(self, data: bytes, send: Send) -> None:
        reply = bytearray(data)
        self.replies += 1
        if self.corrupt_every and self.replies % self.corrupt_every == 0:
            reply[-1] ^= 0x5A  # the CRC's last byte
            self.corrupted += 1
        if self.garbage and self.rng.random() < 0.3:
            reply[:0] = self._garbage()  # garbage before the frame
        send(bytes(reply))
        if self.garbage and self.rng.random() < 0.3:
            asyncio.get_running_loop().call_later(0.002, send, self._garbage())  # between frames


@pytest.mark.asyncio
async def test_garbage_and_bad_crcs_on_an_rtu_line(mosquitto: Broker) -> None:
    sim = units_of(PUMP, DRIVE)
    cable = NoisyCable()
    async with (
        serving_line(sim, cable.open()) as path,
        observing(mosquitto, "modbus/#") as observer,
    ):
        devices = [device(PUMP, "rs485"), device(DRIVE, "rs485")]
        loaded = bridge_config(mosquitto, [rtu_bus(path)], devices)
        async with running_bridge(loaded) as bridge:
            await eventually(lambda: online(observer, PUMP, DRIVE), timeout=20)
            bus = bridge.engine.schedulers["rs485"].counters
            seen = len(observer.log)

            cable.noise(on=True)
            await observer.client.publish("modbus/drive/pd_in_1/set", "-11")
            minus_11 = 0xFFF5  # -11 as the s16 register holds it
            counts = bridge.engine.devices["drive"].writes
            await eventually(lambda: counts.done or errors(observer, DRIVE, seen), timeout=10)
            await eventually(
                lambda: bus.frame_errors >= 4 and cable.corrupted >= 4 and cable.junk >= 4,
                timeout=20,
            )
            cable.noise(on=False)
            if errors(observer, DRIVE, seen):  # refused, or the echo was garbled: not resent
                assert writes_to(sim, DRIVE, PD_IN_1, minus_11) <= 1
            else:
                assert writes_to(sim, DRIVE, PD_IN_1, minus_11) == 1

            before = {unit: sim.value(unit, MOVING[unit]) for unit in (PUMP, DRIVE)}
            for unit in (PUMP, DRIVE):
                sim.set_value(unit, MOVING[unit], before[unit] + 7)  # type: ignore[operator]
            for unit in (PUMP, DRIVE):  # polling recovered: the new values arrive
                topic, key = f"modbus/{NAMES[unit]}", MOVING[unit]
                await eventually(
                    lambda t=topic, k=key, u=unit: (
                        observer.json(t).get(k) == sim.value(u, k) and online(observer, u)
                    ),
                    timeout=20,
                )
            await observer.client.publish("modbus/drive/pd_in_1/set", "12")
            await eventually(lambda: writes_to(sim, DRIVE, PD_IN_1, 12) == 1)
            assert writes_to(sim, DRIVE, PD_IN_1, minus_11) <= 1
    for unit in (PUMP, DRIVE):
        also = {MOVING[unit]: {before[unit]}, "pd_in_1": {0, -11}}
        assert_true_values(published(observer, unit), sim, unit, also=also)


# --- a bus that vanishes -----------------------------------------------------------------------


def watch_opens(
    scheduler: BusScheduler, monkeypatch: pytest.MonkeyPatch
) -> list[tuple[float, bool]]:
    """Record (when, succeeded) of every attempt to open the bus."""
    attempts: list[tuple[float, bool]] = []
    transport = scheduler.transport
    open_bus = transport.open

    async def watched() -> None:
        started = time.monotonic()
        try:
            await open_bus()
        except BusError:
            attempts.append((started, False))
            raise
        attempts.append((started, True))

    monkeypatch.setattr(transport, "open", watched)
    return attempts


def assert_backed_off(attempts: list[tuple[float, bool]]) -> None:
    """After each failed open, the next attempt waited 0.5 s, then 1 s, 2 s, ..."""
    delay = REOPEN_INITIAL
    for (at, ok), (after, _) in itertools.pairwise(attempts):
        if ok:
            delay = REOPEN_INITIAL
            continue
        assert after - at >= delay * 0.999, f"reopened after {after - at:.3f} s, not {delay} s"
        delay *= 2


@pytest.mark.asyncio
async def test_a_serial_port_vanishes_and_comes_back(
    mosquitto: Broker, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The USB adapter is pulled (its port disappears) and plugged in again."""
    sim = units_of(PUMP, DRIVE)
    port = tmp_path / "ttyRS485"  # a stable name, like /dev/serial/by-id/...
    devices = [device(PUMP, "rs485"), device(DRIVE, "rs485")]
    loaded = bridge_config(mosquitto, [rtu_bus(str(port))], devices)
    async with observing(mosquitto, "modbus/#") as observer, contextlib.AsyncExitStack() as cable:
        port.symlink_to(await cable.enter_async_context(serving_line(sim, null_modem())))
        async with running_bridge(loaded) as bridge:
            await eventually(lambda: online(observer, PUMP, DRIVE), timeout=20)
            opens = watch_opens(bridge.engine.schedulers["rs485"], monkeypatch)
            seen = len(observer.log)

            await cable.aclose()  # unplugged: the line goes dead, the port disappears
            port.unlink()
            await eventually(lambda: not online(observer, PUMP) and not online(observer, DRIVE))
            await eventually(lambda: sum(not ok for _, ok in opens) >= 3, timeout=10)
            await observer.client.publish("modbus/drive/pd_in_1/set", "55")
            await eventually(lambda: errors(observer, DRIVE, seen))
            before = sim.value(PUMP, MOVING[PUMP])
            sim.set_value(PUMP, MOVING[PUMP], before + 3)  # type: ignore[operator]

            async with serving_line(sim, null_modem()) as path:  # plugged in again
                port.symlink_to(path)
                await eventually(lambda: online(observer, PUMP, DRIVE), timeout=20)
                key = MOVING[PUMP]
                await eventually(lambda: observer.json("modbus/pump").get(key) == before + 3)
                await asyncio.sleep(0.5)  # a late write would have happened by now
                assert writes_to(sim, DRIVE, PD_IN_1, 55) == 0
                await observer.client.publish("modbus/drive/pd_in_1/set", "56")
                await eventually(lambda: writes_to(sim, DRIVE, PD_IN_1, 56) == 1)
            assert availability(observer, PUMP, seen) == [b"offline", b"online"]
            assert opens[-1][1] is True
            assert_backed_off(opens)
    assert_true_values(published(observer, PUMP), sim, PUMP, also={MOVING[PUMP]: {before}})


@pytest.mark.asyncio
async def test_a_tcp_gateway_goes_away_and_comes_back_on_the_same_port(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sim = units_of(PUMP, DRIVE)
    recorder = Recorder()
    async with contextlib.AsyncExitStack() as gateway:
        port = await gateway.enter_async_context(serving_tcp(sim))
        loaded = config([tcp_bus(port, timeout=0.3)], [device(PUMP), device(DRIVE)])
        engine = Engine(loaded, recorder, policy=FAST_POLICY)
        task = asyncio.create_task(engine.run())
        try:
            pump, drive = engine.devices["pump"], engine.devices["drive"]
            await eventually(lambda: pump.health.online and drive.health.online, timeout=10)
            opens = watch_opens(engine.schedulers["tcp"], monkeypatch)

            await gateway.aclose()  # the gateway is switched off
            await eventually(lambda: pump.health.online is False and drive.health.online is False)
            await eventually(lambda: sum(not ok for _, ok in opens) >= 3, timeout=10)
            before = sim.value(DRIVE, MOVING[DRIVE])
            sim.set_value(DRIVE, MOVING[DRIVE], before + 9)  # type: ignore[operator]

            server = asyncio.create_task(sim.serve_tcp("127.0.0.1", port))  # back, same port
            try:
                await asyncio.wait_for(sim.ready.wait(), 5)
                await eventually(lambda: pump.health.online and drive.health.online, timeout=20)
                await eventually(lambda: drive.values.get(MOVING[DRIVE]) == before + 9)
            finally:
                await cancel(server)
            assert opens[-1][1] is True
            assert_backed_off(opens)
            assert engine.schedulers["tcp"].counters.reopenings >= 3
            assert not task.done()
        finally:
            await cancel(task)
    assert_true_values(iter(u.values for u in recorder.of("pump")), sim, PUMP)
    drive_values = iter(u.values for u in recorder.of("drive"))
    assert_true_values(drive_values, sim, DRIVE, also={MOVING[DRIVE]: {before}})


# --- the broker is killed ----------------------------------------------------------------------


def kill(broker: Broker) -> None:
    """SIGKILL: no clean disconnect, no will, every retained message gone (no persistence)."""
    assert broker.process is not None
    broker.process.kill()
    broker.process.wait(5)
    broker.process = None


def everything_republished(observer: Observer, sim: Simulator) -> bool:
    retained = observer.retained
    return (
        retained.get("modbus/bridge/state") == b"online"
        and "modbus/bridge/devices" in retained
        and online(observer, *THREE)
        and all(f"homeassistant/device/{NAMES[u]}/config" in retained for u in THREE)
        and all(
            f"modbus/{NAMES[u]}" in retained
            and observer.json(f"modbus/{NAMES[u]}").get(MOVING[u]) == sim.value(u, MOVING[u])
            for u in THREE
        )
    )


@pytest.mark.asyncio
async def test_mosquitto_killed_twice_and_restarted(mosquitto: Broker) -> None:
    """Unlike a clean restart (test_bridge), SIGKILL twice, the second time while the bridge
    republishes: it comes back each time with its state, availability, discovery and the
    values that changed meanwhile; the engine polls on while the broker is away."""
    sim = units_of(PUMP, STARTER, DRIVE)
    filters = ("modbus/#", "homeassistant/#")
    async with serving_tcp(sim) as port:
        loaded = bridge_config(mosquitto, [tcp_bus(port)], [device(u) for u in THREE])
        async with running_bridge(loaded) as bridge:
            async with observing(mosquitto, *filters) as observer:
                await eventually(lambda: everything_republished(observer, sim), timeout=20)
            written = {u: sim.value(u, MOVING[u]) for u in THREE}
            for round_ in range(2):
                kill(mosquitto)
                # a kill while a publish awaits its PUBACK is noticed only when aiomqtt
                # gives up waiting (10 s): hence the longer bound
                await eventually(lambda: bridge.mqtt_state == "offline", timeout=30)
                pump = bridge.engine.devices["pump"]
                requests = pump.health.requests
                for unit in THREE:  # the devices change while the broker is away
                    new = written[unit] + 1 + round_  # type: ignore[operator]
                    sim.set_value(unit, MOVING[unit], new)
                await eventually(lambda r=requests, p=pump: p.health.requests > r + 5)
                await asyncio.to_thread(mosquitto.start)  # on the same port
                if round_ == 0:  # killed again as soon as the bridge is back: mid-republish
                    await eventually(lambda: bridge.mqtt_state == "online", timeout=20)
                    continue
                async with observing(mosquitto, *filters) as observer:
                    await eventually(lambda: everything_republished(observer, sim), timeout=30)
                    await observer.client.publish("modbus/drive/pd_in_1/set", "4242")
                    await eventually(lambda: observer.json("modbus/drive").get("pd_in_1") == 4242)
                    assert writes_to(sim, DRIVE, PD_IN_1, 4242) == 1
            assert all(p.health.online for p in bridge.engine.devices.values())


# --- commands while a device is offline -----------------------------------------------------


@pytest.mark.asyncio
async def test_commands_for_a_dead_device_are_refused_and_never_written_later(
    mosquitto: Broker,
) -> None:
    """test_bridge covers one plain /set to an offline device; here both topic forms, a
    command that catches the unit just as it dies (not yet declared offline), and the
    unit's return: exactly one error per command, nothing written late, and a command
    after the return written exactly once."""
    sim = units_of(PUMP, DRIVE)
    async with serving_tcp(sim) as port, observing(mosquitto, "modbus/#") as observer:
        buses = [tcp_bus(port, timeout=0.3, retries=1)]
        loaded = bridge_config(mosquitto, buses, [device(PUMP), device(DRIVE)])
        async with running_bridge(loaded) as bridge:
            await eventually(lambda: online(observer, PUMP, DRIVE), timeout=20)
            drive = bridge.engine.devices["drive"]
            seen = len(observer.log)
            publish = observer.client.publish

            sim.set_quirks(DRIVE, Quirks(dead=True))
            await publish("modbus/drive/pd_in_1/set", "901")  # just as it dies
            await eventually(lambda: drive.health.online is False)
            await eventually(lambda: availability(observer, DRIVE, seen) == [b"offline"])
            await publish("modbus/drive/set", json.dumps({"pd_in_2": 902, "pd_in_3": 903}))
            await publish("modbus/drive/pd_in_4/set", "904")
            await eventually(lambda: len(errors(observer, DRIVE, seen)) >= 4, timeout=10)
            refused = errors(observer, DRIVE, seen)
            assert sorted(e["key"] for e in refused) == ["pd_in_1", "pd_in_2", "pd_in_3", "pd_in_4"]
            assert all("offline" in e["error"] for e in refused if e["key"] != "pd_in_1")

            sim.set_quirks(DRIVE, Quirks())
            await eventually(lambda: online(observer, DRIVE), timeout=10)
            await asyncio.sleep(1.0)  # anything late would have been written by now
            assert not [w for u, w in sim.writes if u == DRIVE]
            await publish("modbus/drive/pd_in_1/set", "905")
            await eventually(lambda: observer.json("modbus/drive").get("pd_in_1") == 905)
            assert writes_to(sim, DRIVE, PD_IN_1, 905) == 1
            assert len(errors(observer, DRIVE, seen)) == 4
    assert_true_values(published(observer, DRIVE), sim, DRIVE, also={"pd_in_1": {0}})
