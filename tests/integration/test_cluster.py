"""Three sites on a 3-node NATS cluster survive each node failure (issue 28).

Three bridges (own simulators, own base topics) on a cluster of three nats-servers
(JetStream, MQTT streams and consumers on 3 replicas); each node is killed in turn with
commands flowing and started again before the next (tests/integration/cluster_sites.py).
Per failure and per site it cut off: the site's values, published by its new session,
reach a subscriber on a surviving node within ``VALUES_WITHIN`` seconds of the bridge saying
online again (the bridge sends them before ``online``; the time from its CONNACK, which on
NATS 2.9 holds a JetStream election, is measured by bench/cluster.py); of the commands
sent once the bridge's command subscription was live again none is lost, none written
twice, none written later than the command expiry (and none of those sent before is
written twice or late either). Once through a load balancer (one URL), once with the three
node URLs and no balancer.

Slow (about a minute per variant): marked ``cluster``, run by ``make test-cluster``, not by
``make test``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.integration.cluster import NatsCluster
from tests.integration.cluster_sites import describe, running_sites

VALUES_WITHIN = 3.0  # seconds from the bridge's online to its values at the subscriber

pytestmark = [
    pytest.mark.cluster,
    pytest.mark.skipif(not NatsCluster.available(), reason="nats-server is not installed"),
]


@pytest.mark.asyncio
@pytest.mark.timeout(400)
@pytest.mark.parametrize("front", ["balancer", "url_list"])
async def test_each_node_killed_in_turn(tmp_path: Path, front: str) -> None:
    cut = 0  # sites cut off, over the three failures (a node may have none by then: the
    # balancer, or a session NATS closed, moved them all to other nodes)
    async with running_sites(tmp_path, balancer=front == "balancer") as cluster:
        for node in range(3):
            failure = await cluster.fail(node)
            said = describe(failure)
            cut += len(failure.sites)
            for site in failure.sites:
                assert site.online is not None and site.live is not None, said
                assert site.connected is not None and site.first_value is not None, said
                assert site.first_value - site.online <= VALUES_WITHIN, said
                assert site.judged(), said  # commands were sent once it was live
                assert site.lost_commands() == [], said
                assert site.duplicated() == [], said
                assert site.late() == [], said
            await cluster.restart(node)
    assert cut, "no node failure cut a site off"
