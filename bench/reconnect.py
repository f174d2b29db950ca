"""How quickly the bridge is back on MQTT after its broker went away.

One soft starter (bench/scale.py's simulator process), the bridge in its own process
(``modbus-mqtt-bridge run -c``), a private mosquitto (no persistence: a restart loses
every retained message, the worst case). Each round kills the broker (SIGKILL, as a
crash or an OOM kill), keeps it down ``OUTAGE`` seconds, and starts it again on the same
port. Measured per round:

* **noticed**: from the kill to the bridge's ``mqtt_down`` log line (it had a publish
  or a keepalive in flight; a killed broker's socket closes at once on loopback);
* **first value**: from the broker accepting connections again to the device's JSON
  state arriving at a subscriber that connected at that moment (the retained copy was
  lost with the broker, so it is the bridge's fresh publish);
* **republished**: how many of the device's values came back (out of all of them).

    .venv/bin/python bench/reconnect.py [rounds]
"""

from __future__ import annotations

import asyncio
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from bench.scale import BRIDGE, MAPPING, bridge_config, listening, process
from bridge.config import MqttConfig
from bridge.mqtt import MqttClient
from tests.integration.mosquitto import Broker
from tests.ports import free_port

OUTAGE = 5.0
DEVICE = "g0-u1"


async def first_state(url: str, within: float = 30.0) -> tuple[float, int]:
    """Seconds until the device's JSON arrives at a new subscriber, and its value count."""
    started = time.monotonic()
    config = MqttConfig(url=url)
    while True:
        try:
            async with MqttClient(config, will_topic="bench/state", client_id="bench") as client:
                await client.subscribe(f"modbus/{DEVICE}", qos=0)
                async with asyncio.timeout(within):
                    async for message in client.messages():
                        document = json.loads(message.payload)
                        values = [k for k in document if k not in ("status", "alarms")]
                        return time.monotonic() - started, len(values)
        except OSError:
            await asyncio.sleep(0.01)


async def noticed(log: Path, since: int, within: float = 30.0) -> float:
    """Seconds until the bridge's log shows a new ``mqtt_down`` line after ``since`` bytes."""
    started = time.monotonic()
    while time.monotonic() - started < within:
        if "MQTT:" in log.read_text(errors="replace")[since:]:
            return time.monotonic() - started
        await asyncio.sleep(0.005)
    return float("inf")


async def main(rounds: int) -> None:
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        broker = Broker(folder)
        broker.start()
        port = free_port()
        serve = [sys.executable, str(Path(__file__).with_name("scale.py")), "serve", "1", str(port)]
        with process(serve, folder / "simulator.log"):
            await listening([port])
            config = bridge_config(folder, broker.url, [port], 1, {"fast": 1.0, "slow": 60.0})
            log = folder / "bridge.log"
            run = [str(BRIDGE), "run", "-c", str(config), "--log-level", "info"]
            with process(run, log):
                _, total = await first_state(broker.url)
                await asyncio.sleep(2)
                found = []
                for _ in range(rounds):
                    size = len(log.read_text(errors="replace"))
                    assert broker.process is not None
                    broker.process.kill()
                    broker.process.wait()
                    broker.process = None
                    seen = await noticed(log, size)
                    await asyncio.sleep(max(0.0, OUTAGE - seen))
                    broker.start()  # same port; returns once it accepts connections
                    back, values = await first_state(broker.url)
                    found.append((seen, back, values))
                    await asyncio.sleep(2)
        broker.stop()
    print(
        f"{MAPPING}, 1 device, fast poll 1 s; broker killed (SIGKILL) and down {OUTAGE:g} s, "
        f"{rounds} rounds\n"
    )
    print("| figure | median | max |")
    print("| --- | ---: | ---: |")
    for label, column in (("noticed ms", 0), ("first value after the broker is back ms", 1)):
        numbers = [1000 * f[column] for f in found]
        print(f"| {label} | {statistics.median(numbers):.0f} | {max(numbers):.0f} |")
    print(f"| values republished | {min(f[2] for f in found)}/{total} | - |")


if __name__ == "__main__":
    asyncio.run(main(int(sys.argv[1]) if len(sys.argv) > 1 else 5))
