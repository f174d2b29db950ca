"""What a restart carries over: the session reads it back before it publishes any state.

A bridge that starts again knows nothing of what it published before, so a counter's
first reading (a 0 from a controller that just powered up, a torn read) would be taken as
it came and Home Assistant would add the whole count again, and every alarm still active
would fire its event once more. At each connect, before the first state goes out,
``carry_over`` reads the retained device documents (``<base>/<device>``, one subscription
for all of them) and hands each device's document to its poller (its counters check their
first reading against the value published last, bridge/core/counters.py; a total counter
keeps its ``last_reset``) and to the state publisher (the alarms it said were active, so
only a change fires: bridge/core/alarm_events.py). A broker that kept nothing (or answers
too slowly: ``SEED_TIMEOUT``) changes nothing; a document over ``MAX_DOCUMENT`` bytes or
that is not a JSON object is ignored.
"""

from __future__ import annotations

import asyncio
import json
import logging

from bridge.core.topics import Topics
from bridge.modbus.engine import Engine
from bridge.mqtt import MqttClient, MqttRefusedError
from bridge.state_publisher import StatePublisher

log = logging.getLogger(__name__)
SEED_TIMEOUT = 1.5  # seconds for the retained documents, SUBACK included
SETTLE = 0.3  # seconds without another retained document: all are in
MAX_DOCUMENT = 256 * 1024  # bytes: a device document is a few KiB


async def carry_over(
    client: MqttClient, topics: Topics, engine: Engine, state: StatePublisher
) -> None:
    """Seed every device's counters and published alarms from its retained document, if
    the broker has one."""
    wanted = {topics.device(device_id): device_id for device_id in engine.devices}
    if not wanted:
        state.carried_over()
        return
    try:
        async with asyncio.timeout(SEED_TIMEOUT):
            found = await client.retained(
                topics.device("+"), settle=SETTLE, keep=wanted.__contains__, limit=len(wanted)
            )
    except (TimeoutError, MqttRefusedError) as exc:
        log.info(
            "the retained device states could not be read (%s): counters and alarms start afresh",
            exc or "no answer",
        )
        found = {}
    for topic, payload in found.items():
        document = _document(payload)
        if document is None:
            log.warning("%s: the retained state is not a device document; ignored", topic)
            continue
        device_id = wanted[topic]
        engine.devices[device_id].seed_counters(document)
        state.seed_alarms(device_id, document)
    state.carried_over()


def _document(payload: bytes) -> dict[str, object] | None:
    if not payload or len(payload) > MAX_DOCUMENT:
        return None
    try:
        document = json.loads(payload)
    except ValueError:
        return None
    return document if isinstance(document, dict) else None
