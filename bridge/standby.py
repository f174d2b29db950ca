"""One bridge per base topic: the check a session makes before it says ``online``.

``check_alone`` reads the retained ``<base>/bridge/state``: ``online`` for another instance
(``<base>/bridge/info``, bridge/core/instance.py) that answers a health check within
``PING_TIMEOUT`` raises BaseTopicTakenError, and the session leaves the broker without a
word and stands by. A retained ``online`` nobody answers (a broker that kept it through a
power cut) is taken over. The retained reads are bounded by ``CHECK_TIMEOUT`` together:
a broker that does not answer the SUBSCRIBE in time (a cluster) does not hold up the
session's state; it goes on as if alone (a second bridge is then found by the
``bridge/info`` it publishes).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging

from bridge.core.instance import Instance, answering_instance, instance_of, taken_message
from bridge.core.topics import Topics
from bridge.mqtt import BaseTopicTakenError, MqttClient, MqttRefusedError
from bridge.mqtt.reconnect import STANDBY_RETRY

log = logging.getLogger(__name__)
ONLINE = b"online"
CHECK_SETTLE = 0.3  # seconds to wait for a retained bridge/state or bridge/info
CHECK_TIMEOUT = 1.5  # seconds for reading both, SUBACKs included
PING_TIMEOUT = 2.0  # seconds for the bridge that bridge/state names to answer


async def check_alone(client: MqttClient, topics: Topics, instance: Instance) -> None:
    """BaseTopicTakenError if another live bridge serves ``topics``' base topic."""
    try:
        async with asyncio.timeout(CHECK_TIMEOUT):
            online, other = await _online_now(client, topics)
    except (TimeoutError, MqttRefusedError) as exc:
        log.info(
            "%s could not be read in time (%s): going on as the only bridge on it",
            topics.bridge_state,
            exc or "no answer",
        )
        return
    if not online or (other is not None and other.id == instance.id):
        return  # nobody online, or this run's own state from before a reconnect
    answered, named = await _answer_of_another(client, topics, instance)
    if answered:
        raise BaseTopicTakenError(taken_message(topics.base, named or other, STANDBY_RETRY))
    log.info(
        "%s says online, but no bridge answers a health check there: taking it over",
        topics.bridge_state,
    )


async def _online_now(client: MqttClient, topics: Topics) -> tuple[bool, Instance | None]:
    """Whether the retained bridge/state says ``online``, and the instance the retained
    bridge/info names then."""
    found = await client.retained(topics.bridge_state, settle=CHECK_SETTLE, limit=1)
    if found.get(topics.bridge_state) != ONLINE:
        return False, None
    found = await client.retained(topics.bridge_info, settle=CHECK_SETTLE, limit=1)
    return True, instance_of(found.get(topics.bridge_info))


async def _answer_of_another(
    client: MqttClient, topics: Topics, instance: Instance
) -> tuple[bool, Instance | None]:
    """Whether a bridge answers a health check on the base topic within PING_TIMEOUT (this
    one does not run requests yet), and the instance it names."""
    transaction = f"instance-check-{instance.id}"
    async with client.watching(topics.bridge_response("health_check")) as following:
        request = json.dumps({"transaction": transaction})
        await client.publish(topics.bridge_request("health_check"), request)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(PING_TIMEOUT):
                while True:
                    answer = (await following()).payload
                    if transaction.encode() in answer:
                        return True, answering_instance(answer)
    return False, None
