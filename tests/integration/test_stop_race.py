"""A stop always stops: SIGTERM ends the bridge within STOP_WITHIN seconds in every state.

In process, the race is driven, not hoped for: a relay between the bridge and the broker
holds the broker's acknowledgements (the session's publishes stay in flight) and cuts the
connection at a chosen moment; the stop (``task.cancel()``, what ``until_stopped`` does on
SIGTERM) comes a chosen number of event-loop turns or milliseconds before or after the
cut. On Python 3.11 a TaskGroup gives a child's error priority over a cancel that arrives
while it aborts: the bridge logged "connection lost; retrying" and reconnected for as long
as the broker stayed away. Then the command itself (``modbus-mqtt-bridge run`` in a
process of its own) gets a real SIGTERM while connecting, reconnecting, serving, with its
bus down, with a write in flight and with the broker holding its acknowledgements.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
import socket
import sys
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig, load_config_data
from bridge.mqtt import MqttClient
from tests.integration.harness import eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.proxy import Relay, relayed
from tests.ports import free_port

STOP_WITHIN = 3.0  # seconds from SIGTERM (or the cancel) to the end
TURNS = tuple(range(-3, 16))  # event-loop turns from the cut to the cancel (< 0: cancel first)
MILLISECONDS = (1, 3, 10, 30, 100, 300, 1000)  # after the cut: in the teardown, the backoff


def pump_config(url: str, port: int, **bus: Any) -> dict[str, Any]:
    """One pump inverter; state and health published all the time (publishes in flight)."""
    return {
        "mqtt": {"url": url, "base_topic": "race", "state_refresh": 0.1},
        "bridge": {"health_interval": 0.1},
        "buses": [
            {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
            | {"timeout": 0.5}
            | bus
        ],
        "devices": [
            {
                "id": "pump",
                "bus": "tcp",
                "unit": 1,
                "mapping": "nastec_vasco",
                "poll": {"fast": 0.2, "slow": 1},
            }
        ],
    }


async def turns(count: int) -> None:
    for _ in range(count):
        await asyncio.sleep(0)


async def stop_around_a_cut(
    relay: Relay, bridge: Bridge, phase: str, *, after: int = 0, ms: float = 0
) -> float:
    """Run the bridge until ``phase`` (``start``: its session waits for SUBACKs, the
    check of its base topic among them; ``serving``: publishes wait for their PUBACKs), then cut and cancel
    ``after`` turns (and ``ms`` milliseconds) apart (the cancel first when ``after`` < 0);
    seconds from the cancel to the end of run()."""
    relay.hold_after = 2 if phase == "start" else None
    task = asyncio.create_task(bridge.run())
    try:
        if phase == "start":  # the CONNACK and one SUBACK passed; the rest is held
            await eventually(lambda: relay.hold, 10)
        else:
            await eventually(lambda: bridge.mqtt_state == "online", 10)
        if phase == "serving":
            await eventually(lambda: bool(bridge.engine.devices["pump"].values), 10)
            relay.hold = True  # acknowledgements never come: publishes stay in flight
        await asyncio.sleep(0.3)
        if after < 0:
            task.cancel()
            started = time.monotonic()
            await turns(-after)
            relay.cut()
        else:
            relay.cut()
            await turns(after)
            await asyncio.sleep(ms / 1000)
            task.cancel()
            started = time.monotonic()
        await asyncio.wait({task}, timeout=STOP_WITHIN + 5)
        return time.monotonic() - started
    finally:
        if not task.done():
            task.cancel()
            await asyncio.wait({task}, timeout=5)
        relay.mend()


@pytest.mark.asyncio
@pytest.mark.timeout(240)
@pytest.mark.parametrize("phase", ["start", "serving"])
async def test_a_stop_around_a_lost_connection_always_stops(phase: str, mosquitto: Broker) -> None:
    took: dict[str, float] = {}
    pump = simulator((1, "nastec_vasco"))
    async with serving_tcp(pump) as port, relayed(mosquitto) as (relay, url):
        config = pump_config(url, port)
        for count in TURNS:
            bridge = Bridge(load_config_data(config, Path("race.yaml")))
            took[f"{count} turns"] = await stop_around_a_cut(relay, bridge, phase, after=count)
        for ms in MILLISECONDS:
            bridge = Bridge(load_config_data(config, Path("race.yaml")))
            took[f"{ms} ms"] = await stop_around_a_cut(relay, bridge, phase, ms=ms)
    late = {when: round(t, 2) for when, t in took.items() if t > STOP_WITHIN}
    assert not late, f"stops that took longer than {STOP_WITHIN} s after the cut: {late}"


# --- the command, stopped by a real SIGTERM ------------------------------------------------


@contextlib.asynccontextmanager
async def bridge_process(
    tmp_path: Path, config: dict[str, Any]
) -> AsyncIterator[asyncio.subprocess.Process]:
    path = tmp_path / "config.yaml"
    path.write_text(json.dumps(config))  # JSON is YAML
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "bridge.cli",
        "run",
        "-c",
        str(path),
        "--log-level",
        "debug",
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        yield process
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()


async def catching_sigterm(pid: int, within: float = 30.0) -> None:
    """Until the process catches SIGTERM (``until_stopped`` set its handler: SigCgt in
    /proc): a signal before that, while Python starts on a loaded machine, would test the
    interpreter's default, not the bridge's stop."""
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        status = Path(f"/proc/{pid}/status").read_text()
        caught = next(line for line in status.splitlines() if line.startswith("SigCgt:"))
        if int(caught.split()[1], 16) & (1 << (signal.SIGTERM - 1)):
            return
        await asyncio.sleep(0.02)
    raise AssertionError(f"the bridge did not catch SIGTERM within {within} s")


async def stopped_after(
    process: asyncio.subprocess.Process,
    ready: Callable[[], Awaitable[None]],
    again: float | None = None,
) -> tuple[float, str]:
    """SIGTERM once ``ready`` returns (and once more ``again`` seconds later); seconds until
    the process ended, and its log."""
    assert process.stderr is not None
    log: list[bytes] = []

    async def read() -> None:
        assert process.stderr is not None
        while line := await process.stderr.readline():
            log.append(line)

    reading = asyncio.create_task(read())
    await catching_sigterm(process.pid)
    await ready()
    process.send_signal(signal.SIGTERM)
    started = time.monotonic()
    if again is not None:
        await asyncio.sleep(again)
        process.send_signal(signal.SIGTERM)
    try:
        async with asyncio.timeout(STOP_WITHIN + 7):
            await process.wait()
    except TimeoutError:
        pass
    took = time.monotonic() - started
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(2):
            await reading
    return took, b"".join(log).decode(errors="replace")


async def retained_online(broker: Broker, device: str = "pump") -> None:
    config = MqttConfig(url=broker.url)
    topic = f"race/{device}/availability"
    async with MqttClient(config, will_topic="watcher/state", client_id="watcher") as client:
        async with asyncio.timeout(15):
            while (await client.retained(topic, settle=0.2)).get(topic) != b"online":
                await asyncio.sleep(0.2)


@contextlib.contextmanager
def silent_listener(*, full_backlog: bool) -> Any:
    """A TCP port that takes connections and never answers; with ``full_backlog`` its
    queue is full, so a new connect gets no SYN-ACK and blocks (paho waits 5 s)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(0)
    fillers = []
    try:
        if full_backlog:
            for _ in range(3):
                filler = socket.socket()
                filler.setblocking(False)
                with contextlib.suppress(BlockingIOError):
                    filler.connect(server.getsockname())
                fillers.append(filler)
        yield server.getsockname()[1]
    finally:
        for each in (*fillers, server):
            each.close()


STATES = (
    "serving",
    "broker refused",
    "broker silent",
    "broker drops the SYN",
    "bus down",
    "device silent",
    "write in flight",
    "acknowledgements held",
    "connection cut",
)


@pytest.mark.asyncio
@pytest.mark.timeout(120)
@pytest.mark.parametrize("state", STATES)
async def test_sigterm_ends_the_bridge_within_seconds(
    state: str, mosquitto: Broker, tmp_path: Path
) -> None:
    sim = simulator((1, "nastec_vasco"), write_latency=30.0 if state == "write in flight" else 0.0)
    async with contextlib.AsyncExitStack() as stack:
        port = await stack.enter_async_context(serving_tcp(sim))
        url = mosquitto.url
        bus: dict[str, Any] = {}
        relay: Relay | None = None
        if state == "broker refused":
            url = f"mqtt://127.0.0.1:{free_port()}"
        elif state in ("broker silent", "broker drops the SYN"):
            silent = stack.enter_context(
                silent_listener(full_backlog=state == "broker drops the SYN")
            )
            url = f"mqtt://127.0.0.1:{silent}"
        elif state in ("acknowledgements held", "connection cut"):
            relay, url = await stack.enter_async_context(relayed(mosquitto))
        elif state == "bus down":
            port = free_port()
        elif state == "device silent":
            port = stack.enter_context(silent_listener(full_backlog=False))
        elif state == "write in flight":
            bus = {"timeout": 40.0}
        process = await stack.enter_async_context(
            bridge_process(tmp_path, pump_config(url, port, **bus))
        )
        ready = ready_for(state, mosquitto, relay)
        took, text = await stopped_after(process, ready)
    assert process.returncode is not None, (
        f"{state}: still running {took:.1f} s after SIGTERM:\n{text[-3000:]}"
    )
    assert took < STOP_WITHIN, f"{state}: ended {took:.1f} s after SIGTERM:\n{text[-3000:]}"
    assert process.returncode == 0, f"{state}: exit {process.returncode}:\n{text[-3000:]}"
    assert "Traceback" not in text, text[-3000:]


def ready_for(state: str, broker: Broker, relay: Relay | None) -> Callable[[], Awaitable[None]]:
    """What to wait for before the signal, in each state."""
    if state in (
        "broker refused",
        "broker silent",
        "broker drops the SYN",
        "bus down",
        "device silent",
    ):

        async def settle() -> None:
            await asyncio.sleep(1.5)  # connecting, retrying, polling a dead device

        return settle
    if state == "write in flight":

        async def writing() -> None:
            await retained_online(broker)
            async with MqttClient(
                MqttConfig(url=broker.url), will_topic="cmd/state", client_id="cmd"
            ) as client:
                await client.publish("race/pump/set", '{"start_stop": false}')
            await asyncio.sleep(1.0)  # the write went out; its answer is 30 s away

        return writing
    assert relay is not None or state == "serving"

    async def online_then() -> None:
        await retained_online(broker)
        if state == "acknowledgements held" and relay is not None:
            relay.hold = True
            await asyncio.sleep(0.5)
        if state == "connection cut" and relay is not None:
            relay.cut()
            await asyncio.sleep(0.05)

    return online_then


@pytest.mark.asyncio
@pytest.mark.timeout(90)
@pytest.mark.parametrize(
    ("again", "code", "earliest", "latest"),
    [
        (0.0, 0, 1.5, STOP_WITHIN),  # one stop delivered twice: the write in flight finishes
        (1.3, 128 + signal.SIGTERM, 1.2, 1.9),  # a second stop: at once, the write cut short
    ],
)
async def test_a_second_signal_ends_the_stop_at_once_unless_it_is_the_first_twice(
    mosquitto: Broker, tmp_path: Path, again: float, code: int, earliest: float, latest: float
) -> None:
    sim = simulator((1, "nastec_vasco"), write_latency=30.0)  # a stop waits FINISH_WRITE (2 s)
    async with serving_tcp(sim) as port:
        config = pump_config(mosquitto.url, port, timeout=40.0)
        async with bridge_process(tmp_path, config) as process:
            ready = ready_for("write in flight", mosquitto, None)
            took, text = await stopped_after(process, ready, again=again)
    assert process.returncode == code, text[-3000:]
    assert earliest <= took <= latest, f"ended {took:.1f} s after the first signal:\n{text[-3000:]}"
    said = "a second stop signal: exiting now" in text
    assert said is (code != 0), text[-3000:]
