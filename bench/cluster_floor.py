"""The floor under bench/cluster.py: what a node failure costs a plain MQTT client on the
same 3-node NATS cluster, no bridge involved (issue 28).

Per failure (node ``k`` killed with SIGKILL, each node in turn, ``rounds`` times): a client
connects to node ``k+1`` right after the kill (again at once after each failed attempt, as
the bridge's URL list does), and as soon as its CONNACK came publishes a plain QoS 0
message and then the retained QoS 1 message a bridge's state is; a QoS 0 subscriber on node
``k+2``, connected before the kill, times their arrival. Milliseconds from the kill:

* **connected**: the CONNACK (NATS closes a CONNECT it cannot serve after its 4 s JetStream
  API timeout; the failed attempts are counted);
* **plain**: the QoS 0 message at the subscriber (core NATS, no JetStream);
* **retained**: the retained message at the subscriber (NATS 2.9 stores a retained message
  in its ``$MQTT_rmsgs`` stream before it passes it on);
* **puback**: its PUBACK (stored in ``$MQTT_msgs`` too; nan: NATS closed the connection
  instead, the store having failed after 4 s).

    .venv/bin/python bench/cluster_floor.py [rounds]
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the cluster of the tests

from bridge.config import MqttConfig
from bridge.mqtt import MqttClient, MqttError
from tests.integration.brokers import NatsBroker
from tests.integration.cluster import NatsCluster
from tests.integration.cluster_sites import _usable

FIGURES = ("connected", "plain", "retained", "puback")


async def settled(cluster: NatsCluster) -> None:
    async with asyncio.timeout(90):
        for url in cluster.urls:
            while not await _usable(url):
                await asyncio.sleep(0.3)


async def connect(url: str, *, within: float = 60.0) -> tuple[MqttClient, int]:
    """A connected client on ``url`` and the failed attempts before it."""
    config = MqttConfig(url=url, version="3.1.1", keepalive=10)
    failed = 0
    deadline = time.monotonic() + within
    while True:
        client = MqttClient(config, will_topic="floor/state", announce=False)
        try:
            await client.__aenter__()
        except MqttError:
            failed += 1
            if time.monotonic() > deadline:
                raise
            continue
        return client, failed


async def one_failure(cluster: NatsCluster, node: int, round_: int) -> dict[str, float]:
    nodes = len(cluster.urls)
    survivor, watcher = cluster.urls[(node + 1) % nodes], cluster.urls[(node + 2) % nodes]
    arrivals: dict[str, float] = {}
    config = MqttConfig(url=watcher, version="3.1.1", keepalive=10)
    async with MqttClient(config, will_topic="watcher/state", announce=False) as subscriber:
        await subscriber.subscribe("floor/#", qos=0)
        value = f"{round_}-{node}".encode()

        async def watch() -> None:
            async for message in subscriber.messages():
                if message.payload == value and not message.retain:
                    arrivals.setdefault(message.topic, time.monotonic())

        watching = asyncio.create_task(watch())
        killed = time.monotonic()
        await asyncio.to_thread(cluster.kill, node)
        client, failed = await connect(survivor)
        connected = time.monotonic()
        acked = math.nan  # NATS closes the connection when it cannot store a QoS 1 publish
        try:
            await client.publish("floor/plain", value, qos=0)
            with contextlib.suppress(MqttError):
                await client.publish("floor/retained", value, qos=1, retain=True)
                acked = time.monotonic()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(30):
                    while len(arrivals) < 2:
                        await asyncio.sleep(0.01)
        finally:
            watching.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watching
            with contextlib.suppress(MqttError):
                await client.__aexit__(None, None, None)
    await asyncio.to_thread(cluster.start, node)
    await settled(cluster)
    ms = {
        "connected": connected,
        "plain": arrivals.get("floor/plain", math.nan),
        "retained": arrivals.get("floor/retained", math.nan),
        "puback": acked,
    }
    row = {k: 1000 * (v - killed) for k, v in ms.items()}
    row["failed"] = failed
    return row


async def main(rounds: int) -> None:
    rows: list[tuple[int, dict[str, float]]] = []
    with tempfile.TemporaryDirectory() as name:
        cluster = NatsCluster(Path(name))
        await asyncio.to_thread(cluster.start)
        try:
            await settled(cluster)
            for round_ in range(rounds):
                for node in range(len(cluster.urls)):
                    rows.append((node, await one_failure(cluster, node, round_)))
        finally:
            await asyncio.to_thread(cluster.stop)
    version = ".".join(map(str, NatsBroker.version()))
    print(f"NATS {version}, 3 nodes (JetStream, MQTT R3), a plain client; ms from the kill\n")
    print("| node | " + " | ".join(FIGURES) + " | retained after CONNACK | failed connects |")
    print("| ---: | " + " | ".join("---:" for _ in FIGURES) + " | ---: | ---: |")
    for node, row in rows:
        after = row["retained"] - row["connected"]
        figures = " | ".join(f"{row[f]:.0f}" for f in FIGURES)
        print(f"| {node} | {figures} | {after:.0f} | {row['failed']:.0f} |")
    print()
    afters = [r["retained"] - r["connected"] for _, r in rows if not math.isnan(r["retained"])]
    print(
        f"retained after CONNACK: median {statistics.median(afters):.0f} ms, "
        f"max {max(afters):.0f} ms; over 3000 ms: {sum(a > 3000 for a in afters)} of {len(afters)}"
    )


if __name__ == "__main__":
    asyncio.run(main(int(sys.argv[1]) if len(sys.argv) > 1 else 2))
