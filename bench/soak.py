"""Memory soak: the bridge's RSS over a long run at 20 polls per second, with commands.

Ten soft starters on one simulated Modbus TCP gateway poll their fast class every 0.5 s
(20 device polls per second, 60 reads) and their settings every 5 s; readings wander
every second, so state messages flow, and a ``motor_run`` command goes to one unit after
another every second (write, read back, publish). The bridge runs in its own process
(``modbus-mqtt-bridge run -c`` on a generated config), with the simulator and a private
mosquitto (``tests/integration/mosquitto.py``) in others, as in ``bench/scale.py``.

``VmRSS`` of the bridge is sampled every ``duration / 60`` seconds (every fourth is
printed); the slope is a least squares line through the samples after the first fifth
of the run (start-up allocations and caches filling), in MiB per hour; the last
``<base>/bridge/health`` report shows the work done.

    .venv/bin/python bench/soak.py [minutes]
"""

from __future__ import annotations

import asyncio
import itertools
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from scale import bridge_process, cpu_seconds, memory_kib

from bridge.config import MqttConfig
from bridge.mqtt import MqttClient
from tests.integration.mosquitto import Broker

UNITS = 10
POLL = {"fast": 0.5, "slow": 5.0}
SAMPLES = 60  # RSS samples; every fourth is printed, all go into the slope


async def commands(client: MqttClient) -> None:
    """One ``motor_run`` command per second, unit after unit: a round of ON, then of OFF."""
    for sent in itertools.count():
        on = (sent // UNITS) % 2 == 0
        await client.publish(f"modbus/g0-u{sent % UNITS + 1}/motor_run/set", "ON" if on else "OFF")
        await asyncio.sleep(1)


async def soak(minutes: float) -> tuple[list[tuple[float, float]], dict[str, Any], float]:
    """(minutes since start, RSS MiB) samples, the last health document, CPU % of a core."""
    health: list[dict[str, Any]] = []
    samples: list[tuple[float, float]] = []
    with tempfile.TemporaryDirectory() as name:
        broker = Broker(Path(name))
        broker.start()
        try:
            async with bridge_process(Path(name), broker.url, UNITS, 1, POLL) as (pid, _):
                config = MqttConfig(url=broker.url)
                async with MqttClient(config, will_topic="bench/state", client_id="soak") as c:
                    await c.subscribe("modbus/bridge/health")
                    started, cpu = time.monotonic(), cpu_seconds(pid)
                    async with asyncio.TaskGroup() as group:
                        sending = group.create_task(commands(c))
                        listening = group.create_task(collect(c, health))
                        step = minutes * 60 / SAMPLES
                        for index in range(SAMPLES + 1):
                            await asyncio.sleep(max(0.0, started + index * step - time.monotonic()))
                            elapsed = time.monotonic() - started
                            samples.append((elapsed / 60, memory_kib(pid, "VmRSS") / 1024))
                        sending.cancel()
                        listening.cancel()
                    usage = 100 * (cpu_seconds(pid) - cpu) / (time.monotonic() - started)
        finally:
            broker.stop()
    return samples, health[-1] if health else {}, usage


async def collect(client: MqttClient, into: list[dict[str, Any]]) -> None:
    async for message in client.messages():
        into.append(json.loads(message.payload))


def slope(points: list[tuple[float, float]]) -> float:
    """Least squares slope of (minutes, MiB), in MiB per hour."""
    xs, ys = zip(*points, strict=True)
    return 60 * statistics.linear_regression(xs, ys).slope


def main(minutes: float) -> None:
    samples, health, cpu = asyncio.run(soak(minutes))
    settled = [s for s in samples if s[0] >= minutes / 5]
    print(
        f"{UNITS} soft starters, fast poll {POLL['fast']} s ({UNITS / POLL['fast']:.0f} polls/s), "
        f"slow {POLL['slow']} s, one command per second; {minutes:g} min\n"
    )
    print("| minute | RSS MiB |")
    print("| ---: | ---: |")
    for at, rss in samples[::4]:
        print(f"| {at:.1f} | {rss:.1f} |")
    rss = [r for _, r in settled]
    print(
        f"\nAfter minute {minutes / 5:g}: RSS {min(rss):.1f} to {max(rss):.1f} MiB, slope "
        f"{slope(settled):+.2f} MiB/h; bridge CPU {cpu:.1f} % of a core."
    )
    if health:
        bus = health["buses"]["g0"]
        writes = sum(d["writes_done"] for d in health["devices"].values())
        print(
            f"Work done: {bus['requests']} bus requests, {bus['timeouts']} timeouts, "
            f"{writes} commands written (last health report, uptime {health['uptime_s']:.0f} s)."
        )


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 30.0)
