"""Three sites on a 3-node NATS cluster survive each node failure (issue 28).

Three bridges (own simulators, own base topics) on a cluster of three nats-servers
(JetStream, MQTT streams and consumers on 3 replicas); each node is killed in turn with
commands flowing and started again before the next (tests/integration/cluster_sites.py).
Per failure and per site it cut off: the site's values reach a subscriber on a surviving
node within ``VALUES_WITHIN`` seconds of the bridge saying online again; of the commands
sent once the bridge's command subscription was live again none is lost, none written
twice, none written later than the command expiry (and none of those sent before is
written twice or late either). Once through a load balancer (one URL), once with the three
node URLs and no balancer.

Commands lost after the SUBACK make the test xfail, saying which, and not fail: NATS 2.9.10
acknowledges a new subscription's SUBACK and then, for a second or more after a node
failure, does not deliver QoS 1 messages published to it (docs/brokers.md); every other
check fails the test.

Slow (about a minute per variant): marked ``cluster``, run by ``make test-cluster``, not by
``make test``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.integration.brokers import NatsBroker
from tests.integration.cluster import NatsCluster
from tests.integration.cluster_sites import describe, running_sites

NATS = ".".join(map(str, NatsBroker.version())) if NatsBroker.available() else "-"
VALUES_WITHIN = 3.0  # seconds from the bridge's reconnect to its values at the subscriber

pytestmark = [
    pytest.mark.cluster,
    pytest.mark.skipif(not NatsCluster.available(), reason="nats-server is not installed"),
]


@pytest.mark.asyncio
@pytest.mark.timeout(400)
@pytest.mark.parametrize("front", ["balancer", "url_list"])
async def test_each_node_killed_in_turn(tmp_path: Path, front: str) -> None:
    lost: list[str] = []
    cut = 0  # sites cut off, over the three failures
    async with running_sites(tmp_path, balancer=front == "balancer") as cluster:
        for node in range(3):
            failure = await cluster.fail(node)
            said = describe(failure)
            cut += len(failure.sites)
            if not failure.sites:  # the balancer put every bridge on another node
                assert front == "balancer", f"node {node} cut no site off: {said}"
            for site in failure.sites:
                assert site.online is not None and site.live is not None, said
                assert site.first_value is not None, said
                assert site.first_value - site.online <= VALUES_WITHIN, said
                assert site.judged(), said  # commands were sent once it was live
                assert site.duplicated() == [], said
                assert site.late() == [], said
                if site.lost_commands():
                    lost.append(said)
            await cluster.restart(node)
    assert cut, "no node failure cut a site off"
    if lost:  # NATS 2.9: see docs/brokers.md, "On a cluster"
        pytest.xfail(f"commands lost after the SUBACK on NATS {NATS}: {lost}")
