"""N bursts of S plain values through the bridge's MQTT session, for an instruction count.

``MqttClient.publish_many`` of ``S`` retained plain values (QoS 1, MQTT 5), ``N`` times,
each burst acknowledged before the next, to the broker at ``URL`` (start a private one, e.g.
``tests/integration/mosquitto.py``'s ``Broker``). Under callgrind the count is repeatable on
a loaded machine; the difference between two values of ``N`` over the messages is the cost
of one message (issue 27):

    valgrind --tool=callgrind --callgrind-out-file=/tmp/cg.N \\
        .venv/bin/python bench/publish_burst.py N 300 mqtt://127.0.0.1:PORT
"""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bridge.config import MqttConfig
from bridge.mqtt import MqttClient


async def main(bursts: int, size: int, url: str) -> None:
    async with MqttClient(MqttConfig(url=url, qos=1), will_topic="bench/state") as client:
        for _ in range(bursts):
            burst = [(f"modbus/d{i % 50}/key_{i}", str(i * 1.5), True) for i in range(size)]
            await client.publish_many(burst)


if __name__ == "__main__":
    asyncio.run(main(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]))
