"""The reconnect loop around the session: ``run_with_reconnect(config, will_topic, session)``.

The caller owns the reconnect loop (aiomqtt's way); this is that loop, with a capped
exponential backoff (bridge/core/backoff.py), a standby while another bridge serves the
base topic, and the next node of a cluster after a failure. Once a broker refused MQTT 5,
its reconnects ask for 3.1.1 at once. A broker that only left an MQTT 5 CONNECT unanswered
may be an old one (amqtt) or a stalled one (SIGSTOP, overload) at the moment the bridge
started: on 3.1.1 a command published with retain while the bridge is connected arrives
like a live one, so that fallback is said (WARNING), every reconnect asks for 5 first
again, and while the session runs on 3.1.1 a probe asks the broker for MQTT 5 on a
connection of its own (after ``PROBE_FIRST`` s, then doubling up to ``PROBE_MAX``); once
it answers, the session ends and the bridge reconnects with MQTT 5.

The session (docs/brokers.md, per broker): every connection of one run of the bridge
uses the same client id (``mqtt.client_id``, else ``run_client_id()``, drawn once per
``run_with_reconnect``), with clean start (3.1.1: clean session) and a session expiry of 0,
so the broker keeps nothing of a session once its connection ends. The same id on every
reconnect, to whichever node of a cluster: the broker ends what is left of the previous
connection at once (a half-open one it still believed in says its will then, before this
connection's ``online``, not a keepalive and a half later over it) and NATS deletes the
consumers the previous session left. A new id per run, so two bridges on one base topic
never take each other's connections over (one of them stands by); a connection that a
killed run left half-open therefore still says its will when the broker gives up on it,
unless ``mqtt.client_id`` is set (then a restart takes it over too).
"""

from __future__ import annotations

import asyncio
import functools
import logging
import secrets
import time
from collections.abc import Awaitable, Callable

from bridge.config import MqttConfig
from bridge.core.backoff import BrokerUrls, ReconnectBackoff
from bridge.mqtt.errors import BaseTopicTakenError, MqttConnectError, MqttDisconnectedError
from bridge.mqtt.session import MqttClient, restore_lost_cancel

STANDBY_RETRY = 10.0  # seconds between two looks at a base topic another bridge serves
PROBE_FIRST = 60.0  # seconds on a 3.1.1 fallback taken on silence before asking for 5 again
PROBE_MAX = 900.0  # ... and at most between two probes

_log = logging.getLogger(__name__)


async def run_with_reconnect(
    config: MqttConfig,
    will_topic: str,
    session: Callable[[MqttClient], Awaitable[None]],
    *,
    backoff: ReconnectBackoff | None = None,
    on_state: Callable[[str], None] | None = None,
    first_connect_required: bool = False,
    announce: bool = True,
) -> None:
    """Run ``session`` on a connected client, reconnecting for as long as it takes.

    ``session`` is entered again on every connect, so it subscribes and republishes there.
    After a failed connect or a lost session the loop waits as ``backoff`` says
    (bridge/core/backoff.py: every 0.1-0.4 s while an outage is young, so the bridge is
    back within half a second of a restarted broker, then doubling up to 30 s).
    ``on_state`` hears ``"online"`` after each connect and ``"offline"`` when a session is
    lost. Returns when ``session`` returns; any error other than
    MqttConnectError/MqttDisconnectedError propagates. Each connect is logged at INFO
    (broker and protocol); an outage is logged once when it starts (WARNING) and once
    when it ends. ``first_connect_required`` (the demo): a first connect that fails raises
    its MqttConnectError instead of retrying, so a wrong URL or login is said once, not
    retried forever. ``announce=False``: the session says ``online`` itself
    (``client.announce()``), after its checks; when it raises BaseTopicTakenError, the
    client leaves without a word, ``on_state`` hears ``"standby"``, the error is logged
    once and the loop looks again every ``STANDBY_RETRY`` seconds until the topic is free.
    With several broker URLs (``mqtt.url`` as a list: cluster nodes) each new attempt after
    a failed connect or a lost session goes to the next one (``mqtt.url_order``), so a dead
    node costs one reconnect, not its downtime.
    """
    loop = _Reconnection(config, backoff or ReconnectBackoff(), on_state)
    while True:
        taken: BaseException | None = None
        url = loop.nodes.current
        attempt = config.model_copy(update={"url": url})
        try:
            async with MqttClient(
                attempt,
                will_topic=will_topic,
                client_id=loop.client_id,
                version=loop.version,
                announce=announce,
                on_announced=functools.partial(loop.up, url),
            ) as client:
                loop.version = None if client.silence_fallback else client.protocol
                loop.connected = loop.ever_connected = True
                if client.silence_fallback:
                    loop.fell_back(url)
                    if not await _serve_probing(client, session):
                        return  # the session returned
                    loop.version = "5"  # the probe's answer: this broker speaks 5
                    raise MqttDisconnectedError(f"{url} answers MQTT 5 now: reconnecting with 5")
                await session(client)
            return
        except* BaseTopicTakenError as group:
            taken = group.exceptions[0]
        except* (MqttConnectError, MqttDisconnectedError) as group:
            failure = group.exceptions[0]
            if first_connect_required and not loop.ever_connected:
                raise failure from None
        # a stop that arrived while the session came down may have been swallowed on the
        # way (Python 3.11's TaskGroup gives a child's error priority over the cancel): the
        # task still says it is being cancelled, so it stops instead of reconnecting
        restore_lost_cancel()
        await asyncio.sleep(loop.standby(taken) if taken is not None else loop.down(failure, url))


async def _serve_probing(
    client: MqttClient, session: Callable[[MqttClient], Awaitable[None]]
) -> bool:
    """Run ``session`` on a 3.1.1 session taken on silence while probing for MQTT 5: True
    when the broker answered 5 (the session cancelled), False when the session returned;
    the session's error is raised as the loop knows it."""
    delay = PROBE_FIRST

    async def probing() -> None:
        nonlocal delay
        while True:
            await asyncio.sleep(delay)
            if await client.answers_5():
                return
            delay = min(delay * 2, PROBE_MAX)

    try:
        async with asyncio.TaskGroup() as group:
            probe = group.create_task(probing(), name="mqtt5-probe")
            serving = group.create_task(_awaited(session(client)), name="mqtt-session")
            await asyncio.wait({probe, serving}, return_when=asyncio.FIRST_COMPLETED)
            (serving if probe.done() else probe).cancel()
    except BaseExceptionGroup as failed:  # the session's own error, as the loop knows it
        raise failed.exceptions[0] from None
    return not probe.cancelled()


async def _awaited(work: Awaitable[None]) -> None:
    await work


class _Reconnection:
    """What the reconnect loop remembers between attempts, and what it says."""

    def __init__(
        self,
        config: MqttConfig,
        backoff: ReconnectBackoff,
        on_state: Callable[[str], None] | None,
    ) -> None:
        self.backoff = backoff
        self.on_state = on_state or (lambda _: None)
        self.nodes = BrokerUrls(config.urls, shuffled=config.url_order == "random")
        # one id for every connection of this run (module docstring: the session)
        self.client_id = config.client_id or run_client_id()
        self.version: str | None = None  # what the broker answered last time
        self.warned_fallback = False
        self.outage: str | None = None
        self.standing_by = False
        self.connected = False  # this attempt's session started
        self.ever_connected = False

    def fell_back(self, url: str) -> None:
        """The session runs on 3.1.1 because MQTT 5 went unanswered: said once a run."""
        if self.warned_fallback:
            return
        self.warned_fallback = True
        _log.warning(
            "MQTT: %s left an MQTT 5 CONNECT unanswered and took 3.1.1: a stalled broker, or"
            ' one without MQTT 5 (then set mqtt.version: "3.1.1"). On 3.1.1 a command'
            " published with retain while the bridge is connected cannot be told from a"
            " live one; the bridge asks for MQTT 5 again in %.0f s and at each reconnect",
            url,
            PROBE_FIRST,
            extra={"event": "mqtt_fallback", "broker": url},
        )

    def up(self, url: str, protocol: str) -> None:
        """The session said online."""
        self.backoff.connected(time.monotonic())
        self.nodes.connected()
        _log.info(
            "MQTT %s %s (MQTT %s)",
            "connected to" if self.outage is None else "reachable again:",
            url,
            protocol,
            extra={"event": "mqtt_up", "broker": url, "protocol": protocol},
        )
        if self.standing_by:
            _log.warning("MQTT: the base topic is free again: this bridge takes over")
        self.outage, self.standing_by = None, False
        self.on_state("online")

    def standby(self, taken: BaseException) -> float:
        """Another bridge serves the base topic: said once; seconds until the next look."""
        _log.log(logging.DEBUG if self.standing_by else logging.ERROR, "%s", taken)
        self.standing_by, self.connected = True, False
        self.on_state("standby")
        return STANDBY_RETRY

    def down(self, failure: BaseException, url: str) -> float:
        """A failed connect or a lost session: said once per outage; seconds to wait."""
        reason = str(failure)
        refused = isinstance(failure, MqttConnectError) and failure.refused
        if self.connected:
            self.on_state("offline")
        self.connected = False
        wait = self.nodes.failed()
        delay = self.backoff.failed(time.monotonic(), refused=refused) if wait else 0.0
        if self.outage is None:
            _log.warning(
                "MQTT: %s; retrying every %.1f s or later",
                reason,
                delay,
                extra={"event": "mqtt_down", "broker": url},
            )
            self.outage = reason
        else:
            _log.debug("MQTT still unavailable: %s", reason)
        if not wait:
            _log.info("MQTT: trying the next broker, %s", self.nodes.current)
        return delay


def run_client_id() -> str:
    """A client id for one run of the bridge: ``modbusbridge`` and 10 random hex digits
    (22 characters from MQTT 3.1.1's safe set: every broker takes it)."""
    return f"modbusbridge{secrets.token_hex(5)}"
