"""The floors under issue 13's two unmet targets: what a process pays for the libraries
this project is built on (pydantic, asyncio, pymodbus, paho/aiomqtt, PyYAML) before any of
its own work.

Memory: one fresh interpreter imports what ``run`` needs, one group after the other, and
prints its RSS (``/proc/self/status``) after each; then the bridge's config and mapping
models, a one-device config validated, and the rest of ``run``. Its ``VmHWM`` at the end
is the peak of a ``run`` that has not polled yet.

CPU: the peers workload of ``bench/peers.py`` (one Nastec VASCO, 40 registers one per
request every second, 20 ms per transaction, the simulator behind its relay in its own
process) read by a bare pymodbus client that does nothing with the values (the floor of
any bridge on pymodbus), then by this bridge with its defaults (publishing to a private
mosquitto), then with ``mqtt.output: values`` (the peers bench's second config). CPU is
utime + stime of the process over the window; ``--profile DIR`` runs each bridge under
cProfile into ``DIR/<config>.prof`` (its figures then include the profiler's cost).

Publish (issue 27): the cost of one plain value (``mqtt.output: values``) against paho's
own. The peers workload's 40 values as plain topics (``modbus/pump/<key>``, retained, QoS
1, MQTT 5) in bursts of 40, each burst acknowledged before the next, to a private
mosquitto: first by a bare paho client driving its own loop (``loop()``, TCP_NODELAY like
the bridge's socket), then by the bridge's MQTT session (``MqttClient.publish_many``, the
payloads made by ``plain_payload`` and the topics by ``Topics`` each burst, as
``StatePublisher`` does). CPU is ``time.process_time()`` of this one process around each;
the two alternate, ``--rounds`` times, and the medians are printed.

    .venv/bin/python bench/floor.py [--seconds 30] [--profile DIR]
    .venv/bin/python bench/floor.py publish [--rounds 3] [--bursts 250]
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from latency import NodelayBroker
from peer_configs import UNIT, registers, write_configs
from scale import cpu_seconds, listening, process

from bridge.config import MqttConfig
from bridge.core.codec import Value
from bridge.core.state import plain_payload
from bridge.core.topics import Topics
from bridge.mqtt import MqttClient
from tests.ports import free_port

BRIDGE = Path(sys.executable).with_name("modbus-mqtt-bridge")
WARMUP = 5.0
PERIOD = 1.0

# Cumulative import steps of one interpreter: (label, statement). {config} is a path.
STEPS = (
    ("the interpreter", "pass"),
    ("asyncio (it imports ssl, OpenSSL, whatever the broker)", "import asyncio"),
    ("PyYAML (with libyaml)", "import yaml"),
    ("pydantic and pydantic-core", "from pydantic import BaseModel, Field, SecretStr"),
    ("pymodbus client", "import pymodbus.client"),
    ("paho-mqtt and aiomqtt", "import aiomqtt"),
    ("the bridge's config and mapping models", "import bridge.config, bridge.core.mapping"),
    ("a one-device config validated", "bridge.config.load_config(Path({config!r}))"),
    ("the rest of `run` (engine, MQTT edge, app)", "import bridge.app"),
)
LIBRARIES = 6  # the first six steps: the libraries alone

CHILD = """
import sys
from pathlib import Path
def kib(field):
    for line in open('/proc/self/status'):
        if line.startswith(field):
            return int(line.split()[1])
for statement in sys.argv[1:]:
    exec(statement)
    print(kib('VmRSS:'), flush=True)
print(kib('VmHWM:'))
"""

CONFIG = """\
mqtt: {{url: "mqtt://127.0.0.1:1"}}
buses: [{{id: tcp, transport: tcp, host: 127.0.0.1, tcp_port: {port}}}]
devices: [{{id: starter, bus: tcp, unit: 1, mapping: soft_starter}}]
"""


def memory(folder: Path) -> None:
    config = folder / "memory.yaml"
    config.write_text(CONFIG.format(port=free_port()))
    statements = [s.format(config=str(config)) for _, s in STEPS]
    out = subprocess.run(  # noqa: S603 - our own interpreter and statements
        [sys.executable, "-c", CHILD, *statements], capture_output=True, text=True, check=True
    ).stdout.split()
    rss, hwm = [int(k) / 1024 for k in out[:-1]], int(out[-1]) / 1024
    print("| what | RSS after, MiB | step, MiB |\n| --- | ---: | ---: |")
    for i, ((label, _), after) in enumerate(zip(STEPS, rss, strict=True)):
        step = f"+{after - rss[i - 1]:.1f}" if i else f"{after:.1f}"
        print(f"| {label} | {after:.1f} | {step} |")
        if i == LIBRARIES - 1:
            print(f"| **the libraries alone** | **{after:.1f}** | |")
    print(f"| peak (VmHWM) at the end | {hwm:.1f} | |\n")


async def bare_client(port: int, seconds: float) -> None:
    """The peers workload read by pymodbus alone, every register every second, until
    ``seconds`` have passed; the values are dropped."""
    from pymodbus.client import AsyncModbusTcpClient  # noqa: PLC0415 - the child's own

    addresses = [r.address + word for r in registers() for word in range(r.words)]
    client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=1, retries=0)
    await client.connect()
    end = time.monotonic() + seconds
    tick = time.monotonic()
    while (now := time.monotonic()) < end:
        for address in addresses:  # one register per request, as the device demands
            await client.read_holding_registers(address, count=1, device_id=UNIT)
        tick += PERIOD
        await asyncio.sleep(max(0.0, tick - now))
    client.close()


async def cpu_of(argv: list[str], log: Path, seconds: float) -> float:
    """% of one core the process of ``argv`` takes over ``seconds`` after the warm-up."""
    with process(argv, log) as child:
        await asyncio.sleep(WARMUP)
        before, start = cpu_seconds(child.pid), time.monotonic()
        await asyncio.sleep(seconds)
        return 100 * (cpu_seconds(child.pid) - before) / (time.monotonic() - start)


async def cpu(folder: Path, seconds: float, profile: Path | None = None) -> None:
    port, log = free_port(), folder / "requests.log"
    serve = [sys.executable, str(Path(__file__).with_name("peers.py")), "serve", str(port)]
    broker = NodelayBroker(folder)
    broker.start()
    try:
        with process([*serve, "0.02", str(log)], folder / "device.log"):
            await listening([port])
            bare = [sys.executable, __file__, "client", str(port), str(seconds + WARMUP + 5)]
            floor = await cpu_of(bare, folder / "client.log", seconds)
            configs = write_configs(folder, broker.url, port, [UNIT])
            figures = [("pymodbus alone, values dropped", floor)]
            for name, label in (("bridge", "this bridge"), ("bridge-values", "output: values")):
                run = [str(BRIDGE), "run", "-c", str(configs[name]), "--log-level", "warning"]
                if profile is not None:
                    out = profile / f"{name}.prof"
                    run = [sys.executable, "-m", "cProfile", "-o", str(out), *run]
                figures.append((label, await cpu_of(run, folder / f"{name}.log", seconds)))
    finally:
        broker.stop()
    reads = sum(r.words for r in registers())
    print(f"| {reads} reads a second, {seconds:g} s window | CPU % of one core | per read, ms |")
    print("| --- | ---: | ---: |")
    for label, figure in figures:
        print(f"| {label} | {figure:.2f} | {10 * figure / reads / PERIOD:.3f} |")


def paho_floor(port: int, messages: list[tuple[str, str]], bursts: int) -> float:
    """CPU seconds a bare paho client takes to publish ``messages`` ``bursts`` times, each
    burst acknowledged (QoS 1, retained) before the next."""
    import paho.mqtt.client as paho  # noqa: PLC0415 - only this part needs it

    client = paho.Client(paho.CallbackAPIVersion.VERSION2, "floor", protocol=paho.MQTTv5)
    acked = 0

    def on_publish(*_: object) -> None:
        nonlocal acked
        acked += 1

    client.on_publish = on_publish
    client.connect("127.0.0.1", port)
    client.socket().setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    while not client.is_connected():
        client.loop(0.1)
    start = time.process_time()
    for _ in range(bursts):
        due = acked + len(messages)
        for topic, payload in messages:
            client.publish(topic, payload, 1, True)
        while acked < due:
            client.loop(0.1)
    spent = time.process_time() - start
    client.disconnect()
    return spent


async def bridge_publish(url: str, values: dict[str, Value], bursts: int) -> float:
    """CPU seconds the bridge's MQTT session takes for the same bursts, the plain topics
    and payloads made as ``StatePublisher`` makes them."""
    topics = Topics(base="modbus")
    async with MqttClient(MqttConfig(url=url, qos=1), will_topic="bench/state") as client:
        start = time.process_time()
        for _ in range(bursts):
            burst = [(topics.value("pump", k), plain_payload(v), True) for k, v in values.items()]
            await client.publish_many(burst)
        return time.process_time() - start


async def publish_cost(rounds: int, bursts: int) -> None:
    values: dict[str, Value] = {r.key: float(r.address) / 10 for r in registers()}
    topics = Topics(base="modbus")
    messages = [(topics.value("pump", k), plain_payload(v)) for k, v in values.items()]
    count = bursts * len(messages)
    floors, ours = [], []
    with tempfile.TemporaryDirectory() as name:
        broker = NodelayBroker(Path(name))
        broker.start()
        try:
            for _ in range(rounds):
                floors.append(1e6 * paho_floor(broker.port, messages, bursts) / count)
                ours.append(1e6 * await bridge_publish(broker.url, values, bursts) / count)
        finally:
            broker.stop()
    print(f"{bursts} bursts of {len(messages)} plain values, QoS 1, retained, MQTT 5; CPU us a")
    print(f"message, each of {rounds} rounds and the median\n")
    print("| publisher | rounds, us a message | median, us | vs paho |")
    print("| --- | --- | ---: | ---: |")
    floor = statistics.median(floors)
    for label, found in (("bare paho client (the floor)", floors), ("this bridge", ours)):
        each = ", ".join(f"{f:.0f}" for f in found)
        median = statistics.median(found)
        print(f"| {label} | {each} | {median:.0f} | {median / floor:.2f} |")


async def main(seconds: float, profile: Path | None) -> None:
    with tempfile.TemporaryDirectory() as name:
        if profile is None:
            memory(Path(name))
        await cpu(Path(name), seconds, profile)


if __name__ == "__main__":
    if sys.argv[1:2] == ["client"]:
        asyncio.run(bare_client(int(sys.argv[2]), float(sys.argv[3])))
    elif sys.argv[1:2] == ["publish"]:
        parser = argparse.ArgumentParser(description="the cost of a plain value (issue 27)")
        parser.add_argument("--rounds", type=int, default=3)
        parser.add_argument("--bursts", type=int, default=250)
        options = parser.parse_args(sys.argv[2:])
        asyncio.run(publish_cost(options.rounds, options.bursts))
    else:
        parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
        parser.add_argument("--seconds", type=float, default=30.0)
        parser.add_argument("--profile", type=Path, help="cProfile each bridge run into DIR")
        options = parser.parse_args()
        asyncio.run(main(options.seconds, options.profile))
