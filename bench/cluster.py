"""What a node failure costs three sites on a 3-node NATS cluster (issue 28).

The scenario of tests/integration/test_cluster.py (tests/integration/cluster_sites.py):
three bridges in this process, each with its own simulated drive and base topic, on three
nats-servers (JetStream, MQTT streams and consumers on 3 replicas); each node killed
(SIGKILL) in turn with commands flowing, and started again before the next. Once through
a TCP load balancer (one URL), once with the three node URLs. Per site that a failure cut
off, from the kill:

* **detected**: the bridge saw its connection end;
* **connected**: its CONNACK came (the failed attempts before it are counted: a node that
  takes the connection and does not answer the CONNECT while JetStream elects leaders);
* **online**: its ``online`` was acknowledged (after the base-topic check, at most 1.5 s,
  and, since issue 28, after its state);
* **first value**: its state reached a subscriber (QoS 0) on a node that stayed up (the
  first message on its state topic after the loss);
* **live**: online, with its command subscription acknowledged (SUBACK) again;
* **lost**: commands the broker took after ``live`` (QoS 0, alternating with QoS 1 ones
  it acknowledged) that never reached the drive;
* **value - connack**: from the CONNACK to the first value (what the bridge adds to the
  cluster's own reconnect time: bench/cluster_floor.py measures a plain client's).

    .venv/bin/python bench/cluster.py [rounds]
"""

from __future__ import annotations

import asyncio
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the cluster of the tests

from bridge.mqtt import session as session_module
from tests.integration.brokers import NatsBroker
from tests.integration.cluster_sites import Failure, running_sites

FIGURES = ("detected", "connected", "online", "first value", "live")


def follow_connects() -> list[tuple[str, float, float, bool]]:
    """(will topic, start, end, ok) of every connect attempt of every bridge."""
    attempts: list[tuple[str, float, float, bool]] = []
    opened = session_module.MqttClient._open

    async def _open(self: Any, *args: Any) -> Any:
        started = time.monotonic()
        try:
            connection = await opened(self, *args)
        except BaseException:
            attempts.append((self._will_topic, started, time.monotonic(), False))
            raise
        attempts.append((self._will_topic, started, time.monotonic(), True))
        return connection

    session_module.MqttClient._open = _open  # type: ignore[method-assign]
    return attempts


def rows(
    failure: Failure, front: str, attempts: list[tuple[str, float, float, bool]]
) -> list[dict[str, Any]]:
    found = []
    for site in failure.sites:
        will = f"site{site.site}/bridge/state"
        mine = [a for a in attempts if a[0] == will and a[1] >= failure.killed]
        connack = next((end for _, _, end, ok in mine if ok), None)
        assert site.online is not None
        before = [a for a in mine if a[2] <= (connack or site.online)]
        found.append(
            {
                "front": front,
                "node": failure.node,
                "site": site.site,
                "failed attempts": sum(1 for a in before if not a[3]),
                "detected": site.lost,
                "connected": connack,
                "online": site.online,
                "first value": site.first_value,
                "live": site.live,
                "lost": len(site.lost_commands()),
                "judged": len(site.judged()),
                "killed": failure.killed,
            }
        )
    return found


def ms(row: dict[str, Any], figure: str) -> float:
    at = row[figure]
    return float("nan") if at is None else 1000 * (at - row["killed"])


async def main(rounds: int) -> None:
    attempts = follow_connects()
    found: list[dict[str, Any]] = []
    for front in ("balancer", "url_list"):
        with tempfile.TemporaryDirectory() as name:
            async with running_sites(Path(name), balancer=front == "balancer") as cluster:
                for _ in range(rounds):
                    for node in range(3):
                        failure = await cluster.fail(node)
                        found += rows(failure, front, attempts)
                        await cluster.restart(node)
    version = ".".join(map(str, NatsBroker.version()))
    print(
        f"NATS {version}, 3 nodes (JetStream, MQTT streams and consumers R3), 3 sites; each "
        f"node killed in turn, {rounds} round(s) per front; ms from the kill\n"
    )
    print(
        "| front | node | site | "
        + " | ".join(FIGURES)
        + " | value - connack | failed connects | lost |"
    )
    print(
        "| --- | ---: | ---: | " + " | ".join("---:" for _ in FIGURES) + " | ---: | ---: | ---: |"
    )
    for row in found:
        figures = " | ".join(f"{ms(row, f):.0f}" for f in FIGURES)
        after = ms(row, "first value") - ms(row, "connected")
        print(
            f"| {row['front']} | {row['node']} | {row['site']} | {figures} | {after:.0f} | "
            f"{row['failed attempts']} | {row['lost']}/{row['judged']} |"
        )
    print()
    print("| front | figure | median | max |")
    print("| --- | --- | ---: | ---: |")
    for front in ("balancer", "url_list"):
        mine = [r for r in found if r["front"] == front]
        for figure in FIGURES:
            numbers = [ms(r, figure) for r in mine if r[figure] is not None]
            if numbers:
                print(
                    f"| {front} | {figure} | {statistics.median(numbers):.0f} | "
                    f"{max(numbers):.0f} |"
                )


if __name__ == "__main__":
    asyncio.run(main(int(sys.argv[1]) if len(sys.argv) > 1 else 1))
