"""Normal operation logs no warning, at any output mode and scale (issue 27, item 3).

aiomqtt logs ``There are N pending publish calls.`` at WARNING for every publish beyond
ten unacknowledged ones: with ``mqtt.output: both`` one Vacon drive's start logged 135 such
lines and 50 devices 16,779 in 40 s. A start of many devices publishing every value is
normal operation: the count of WARNING lines is asserted, not any timing.
"""

from __future__ import annotations

import asyncio
import logging
import re
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.app import Bridge
from bridge.config import load_config_data
from bridge.mqtt import MqttClient
from tests.integration.harness import eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.proxy import relayed
from tests.integration.test_one_bridge import started
from tests.ports import free_port

SEEDS = ("nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100")
# units on one simulated gateway (one bus, one frame in flight): two of each seed model,
# so that no bus is near its capacity on a busy test machine (the Vacon's watchdog wants a
# frame every 2 s, and the bridge says so when it did not get one: the simulator's ticks
# yield between devices, or a busy machine holds every answer for the whole sweep)
PER_GATEWAY = 10


ROOT = Path(__file__).resolve().parents[2]
# the simulated gateways run in a process of their own (as a real site's devices do): the
# test's process is the bridge's alone
SERVE = (
    "import asyncio, sys; from tests.integration.test_quiet_log import serve; serve(sys.argv[1:])"
)


def serve(args: list[str]) -> None:
    """The simulator process: ``devices`` units on the gateways' ports, until killed."""
    devices, ports = int(args[0]), [int(port) for port in args[1:]]

    async def run() -> None:
        async with asyncio.TaskGroup() as group:
            for units, port in zip(gateways_of(devices), ports, strict=True):
                specs = ((local(unit), SEEDS[unit % len(SEEDS)]) for unit in units)
                group.create_task(simulator(*specs, tick=1.0).serve_tcp("127.0.0.1", port))

    asyncio.run(run())


def gateways_of(devices: int) -> list[range]:
    """The devices (1-based) on each gateway, ``PER_GATEWAY`` at most."""
    return [
        range(first, min(first + PER_GATEWAY, devices + 1))
        for first in range(1, devices + 1, PER_GATEWAY)
    ]


async def listening(ports: list[int]) -> None:
    """Until every port takes a connection."""
    for port in ports:

        async def connected(port: int = port) -> bool:
            try:
                _, writer = await asyncio.open_connection("127.0.0.1", port)
            except OSError:
                return False
            writer.close()
            return True

        for _ in range(300):
            if await connected():
                break
            await asyncio.sleep(0.1)


def local(unit: int) -> int:
    """The unit id on its gateway of the ``unit``-th device (1-based)."""
    return (unit - 1) % PER_GATEWAY + 1


async def assert_quiet_start(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture, devices: int, poll: dict[str, float]
) -> None:
    """Start ``devices`` simulated units (the five seed models in turn, ``PER_GATEWAY`` to
    a gateway) with ``output: both``, wait until every one is online and its discovery out,
    then for two more fast polls; assert that no WARNING (or worse) was logged."""
    gateways = gateways_of(devices)
    ports = [free_port() for _ in gateways]
    command = [sys.executable, "-c", SERVE, str(devices), *map(str, ports)]
    with subprocess.Popen(command, cwd=ROOT) as simulators:
        try:
            await listening(ports)
            await quiet_start(mosquitto, caplog, gateways, ports, poll)
        finally:
            simulators.terminate()


async def quiet_start(
    mosquitto: Broker,
    caplog: pytest.LogCaptureFixture,
    gateways: list[range],
    ports: list[int],
    poll: dict[str, float],
) -> None:
    data = {
        "mqtt": {"url": mosquitto.url, "output": "both", "discovery": "device"},
        "buses": [
            # a generous timeout: a test machine shared with others may answer late
            {
                "id": f"gw{i}",
                "transport": "tcp",
                "host": "127.0.0.1",
                "tcp_port": port,
                "timeout": 5.0,
            }
            for i, port in enumerate(ports)
        ],
        "devices": [
            {
                "id": f"d{unit}",
                "bus": f"gw{i}",
                "unit": local(unit),
                "mapping": SEEDS[unit % len(SEEDS)],
                "poll": poll,
                "protocol": {"min_request_interval": 0.0},
            }
            for i, units in enumerate(gateways)
            for unit in units
        ],
    }
    bridge = Bridge(load_config_data(data, Path("many.yaml")))
    with caplog.at_level(logging.WARNING, logger="bridge"):
        async with started(bridge):
            await eventually(
                lambda: all(p.health.online for p in bridge.engine.devices.values()), 180
            )
            await eventually(lambda: not bridge.discovery.pending, 60)
            await asyncio.sleep(2 * poll["fast"])  # state going out, as it always does
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert warnings == [], f"{len(warnings)} warnings, the first: {warnings[:3]}"


@pytest.mark.asyncio
@pytest.mark.timeout(120)
async def test_a_start_of_many_devices_with_every_value_published_logs_no_warning(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    await assert_quiet_start(mosquitto, caplog, 50, {"fast": 1.0, "slow": 5.0})


@pytest.mark.asyncio
@pytest.mark.timeout(300)
async def test_a_start_of_247_devices_with_every_value_published_logs_no_warning(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    """The most units a Modbus address allows (25 gateways): the same."""
    await assert_quiet_start(mosquitto, caplog, 247, {"fast": 2.0, "slow": 30.0})


@pytest.mark.asyncio
@pytest.mark.timeout(120)
async def test_a_broker_slower_than_the_bridge_is_said_once_with_numbers_and_bounded(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    """For 15 s the broker's answers reach the bridge 6 s late (a relay holds them: more
    than ``BACKLOG_SAID_AFTER``, less than the 10 s after which a session gives up) while
    ten devices have their state to send twice a second (asked again, as after a read on
    request, whether their readings moved or not): one WARNING for it, with the numbers; the
    publishes waiting for their acknowledgement never exceed one burst of every device's
    whole state (newer values replace older ones, nothing piles up); the session lives on."""
    units = [(unit, SEEDS[unit % len(SEEDS)]) for unit in range(1, 11)]
    sim = simulator(*units, tick=0.5)
    async with serving_tcp(sim) as port, relayed(mosquitto) as (relay, url):
        data = {
            "mqtt": {"url": url, "output": "both", "discovery": "device"},
            "buses": [{"id": "gw", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}],
            "devices": [
                {
                    "id": f"d{unit}",
                    "bus": "gw",
                    "unit": unit,
                    "mapping": name,
                    "poll": {"fast": 0.5, "slow": 0.5},
                    "protocol": {"min_request_interval": 0.0},
                }
                for unit, name in units
            ],
        }
        bridge = Bridge(load_config_data(data, Path("slow.yaml")))
        sessions: list[MqttClient] = []
        serve = bridge._session

        async def session(client: MqttClient) -> None:  # the bridge's own, remembered
            sessions.append(client)
            await serve(client)

        bridge._session = session  # type: ignore[method-assign]
        devices = bridge.engine.devices.values()
        with caplog.at_level(logging.WARNING, logger="bridge"):
            async with started(bridge):
                await eventually(lambda: all(p.health.online for p in devices), 60)
                # the first session's sweep of stale configs (retained reads, no publish)
                # done, so the publishers run: a delay set before would hold the sweep's
                # SUBACKs 6 s each, and nothing would be published meanwhile
                await eventually(lambda: bridge.discovery.swept, 30)
                relay.delay = 6.0
                most = 0
                for tick in range(150):
                    if tick % 5 == 0:  # state to send, whether the readings moved or not
                        for device_id in bridge.engine.devices:
                            bridge.state.again(device_id)
                    most = max(most, sessions[-1].unacknowledged)
                    await asyncio.sleep(0.1)
                relay.delay = 0.0
                await asyncio.sleep(8)  # the answers held back arrive
                stayed = len(sessions)
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(said) == 1, (said, most, len(sessions))  # most 0: nothing went out meanwhile
    numbers = (
        r"slower than the bridge: it acknowledged nothing for \d+\.\d s; \d+ publishes took "
        r"\d+\.\d s in all, \d+ more wait for theirs"
    )
    assert re.search(numbers, said[0]), said[0]
    burst = sum(len(p.state.published) + 2 for p in devices) + 3  # + devices list, health
    assert 0 < most <= burst, (most, burst)
    assert stayed == 1  # no timeout ended the session
