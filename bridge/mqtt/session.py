"""One broker session: ``async with MqttClient(config, will_topic=...) as client``.

Entering connects (bridge/mqtt/connection.py: mqtt:// or mqtts://, user name and password,
the Last Will ``offline``) with MQTT 5, falling back to 3.1.1 when the broker refuses 5 or
takes the connection but never answers an MQTT 5 CONNECT, as amqtt does, then publishes
``online`` on the will topic (retained; or the caller does, ``announce()``, after its
checks). Leaving cleanly (the session returned or was cancelled: a stop) publishes the
caller's ``farewell`` messages (retained: devices going offline, or empty payloads that
remove what the session published, ``retained_topics``), then ``goodbye`` on the will
topic (``offline``; empty removes it), all at once (also when the session published
retained messages before its ``online``), and disconnects once the broker
acknowledged them all; if it did not within ``FAREWELL_TIMEOUT`` seconds, the socket is
closed without DISCONNECT, so the broker publishes the will. Incoming messages are
``Message`` values, decoupled from paho. The caller owns the reconnect loop
(bridge/mqtt/reconnect.py).

Safety on MQTT 5: ``subscribe(..., live_only=True)`` asks the broker not to send retained
messages at all (retain handling 2) and to keep the retain flag of live ones (retain as
published), so the caller can refuse a command published with retain; ``Message.expiry``
carries the publisher's message expiry interval (the time it has left).

Anything a broker answers that the protocol does not allow (a SUBACK with the wrong
number of codes, a packet paho cannot parse) ends the session with
MqttDisconnectedError, so the reconnect loop starts a new one; it never ends the process.

One piece, at about 470 lines: entering, serving and leaving share one connection and
what the session promised on it (``announced``, ``retained_topics``, ``farewell``), and
the way out is only correct read beside the way in.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import ssl
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Self

import aiomqtt
from paho.mqtt.subscribeoptions import SubscribeOptions

from bridge.config import MqttConfig
from bridge.mqtt.connection import (
    FAILURE,
    OFFLINE,
    Acknowledgements,
    Connection,
    Received,
    connect,
    tls_context,
)
from bridge.mqtt.errors import (
    BaseTopicTakenError,
    MqttConnectError,
    MqttDisconnectedError,
    MqttError,
    MqttPublishError,
    MqttRefusedError,
    MqttUnackedError,
    MqttUnansweredError,
)

ONLINE = b"online"
_UNSUPPORTED_PROTOCOL_VERSION = 0x84  # CONNACK reason code (3.1.1 return code 1 maps to it)
_CLOSE_TIMEOUT = 2.0  # the goodbye "offline" must not hold up a shutdown
FAREWELL_TIMEOUT = 2.0  # seconds for the farewell messages and the goodbye: a stop ends in 3 s
# seconds without an acknowledgement while some are due: the broker is slower than the
# bridge. Below connection.TIMEOUT (10 s), after which the session ends (the reconnect
# loop says so).
BACKLOG_SAID_AFTER = 5.0

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Message:
    """An incoming message; ``duplicate`` is the DUP flag (a QoS>0 redelivery)."""

    topic: str
    payload: bytes
    qos: int
    retain: bool
    duplicate: bool
    mid: int | None  # the packet identifier of a QoS 1/2 delivery, None for QoS 0
    expiry: float | None = None  # MQTT 5 message expiry: seconds it has left, None: none
    # time.monotonic() when it arrived (it may wait unread); not part of what it says
    received: float | None = field(default=None, compare=False)


class MqttClient:
    """One broker session: ``async with MqttClient(config, will_topic=...) as client``."""

    def __init__(
        self,
        config: MqttConfig,
        *,
        will_topic: str,
        client_id: str | None = None,
        version: str | None = None,
        announce: bool = True,
        on_announced: Callable[[str], None] | None = None,
    ) -> None:
        self._config = config
        self._announce = announce  # False: the caller says ``online`` (``announce()``)
        self._on_announced = on_announced  # hears the protocol once ``online`` is out
        self.announced = False
        self._version = version or config.version  # a known 3.1.1 broker: no MQTT 5 try
        # a broker known to answer MQTT 5 (this run's last session was 5): its silence is a
        # stall (SIGSTOP, overload), not an old broker, and 3.1.1 would lose the retain flag
        # of live commands, so a retained command published meanwhile would run
        self._known_5 = version == "5"
        # 3.1.1 taken after an MQTT 5 CONNECT went unanswered: an old broker (amqtt) or a
        # stalled one; the reconnect loop asks for 5 again (bridge/mqtt/reconnect.py)
        self.silence_fallback = False
        self._will_topic = will_topic
        self._client_id = client_id if client_id is not None else config.client_id
        self._connection: Connection | None = None
        self._protocol: str | None = None
        self._filters: set[str] = set()
        self.retained_topics: set[str] = set()  # retained messages this session left there
        self.farewell: Callable[[], Iterable[tuple[str, str]]] | None = None
        self.goodbye = OFFLINE  # the will topic's last message at a clean close

    @property
    def broker(self) -> str:
        """The URL of the broker this session is on."""
        return self._config.broker_url

    @property
    def client_id(self) -> str:
        """The client id of this connection."""
        return self._require().identifier

    @property
    def protocol(self) -> str:
        """The MQTT version in use, ``"5"`` or ``"3.1.1"`` (after a fallback)."""
        if self._protocol is None:
            raise MqttDisconnectedError("not connected")
        return self._protocol

    async def __aenter__(self) -> Self:
        url = self._config.broker_url
        try:
            context = await asyncio.to_thread(tls_context, self._config)
        except (OSError, ssl.SSLError) as exc:
            raise MqttConnectError(f"{url}: cannot load TLS files: {exc}") from exc
        if self._version == "5":
            try:
                connection = await self._open(aiomqtt.ProtocolVersion.V5, context)
            except MqttConnectError as exc:
                if isinstance(exc, MqttUnansweredError) and self._known_5:
                    raise  # the reconnect loop tries MQTT 5 again
                if isinstance(exc, MqttUnansweredError):
                    _log.info("%s does not answer an MQTT 5 CONNECT; trying 3.1.1", url)
                    self.silence_fallback = True
                elif exc.code == _UNSUPPORTED_PROTOCOL_VERSION:
                    _log.info("%s does not speak MQTT 5; using 3.1.1", url)
                else:
                    raise
                connection = await self._open(aiomqtt.ProtocolVersion.V311, context)
        else:
            connection = await self._open(aiomqtt.ProtocolVersion.V311, context)
        self._connection = connection
        if self._announce:
            try:
                await self.announce()
            except MqttDisconnectedError:
                await self.__aexit__(None, None, None)
                raise
        return self

    async def answers_5(self) -> bool:
        """Whether the broker answers an MQTT 5 CONNECT now: a probe on a connection of its
        own (its own client id, no Last Will, a clean DISCONNECT), this session untouched."""
        try:
            context = await asyncio.to_thread(tls_context, self._config)
            probe = await connect(
                self._config,
                aiomqtt.ProtocolVersion.V5,
                context,
                client_id=f"{self._client_id or 'modbusbridge'}-probe",
                will_topic=None,
            )
        except (MqttConnectError, OSError, ssl.SSLError):
            return False
        try:
            await probe.__aexit__(None, None, None)
        except aiomqtt.MqttError as error:
            _log.debug("the MQTT 5 probe did not disconnect cleanly: %s", error)
        finally:
            probe.abort()
        return True

    async def announce(self) -> None:
        """``online`` on the will topic (retained): from now on a stop says goodbye."""
        try:
            await self.publish(self._will_topic, ONLINE, retain=True)
        except MqttDisconnectedError as exc:
            if self._config.qos == 2:  # the session's first QoS 2 publish
                raise MqttDisconnectedError(
                    f"{exc}; if the broker does not do QoS 2 (NATS before 2.10), set mqtt.qos: 1"
                ) from exc
            raise
        self.announced = True
        if self._on_announced is not None:
            self._on_announced(self.protocol)

    async def _open(
        self, protocol: aiomqtt.ProtocolVersion, context: ssl.SSLContext | None
    ) -> Connection:
        connection = await connect(
            self._config,
            protocol,
            context,
            client_id=self._client_id,
            will_topic=self._will_topic,
        )
        self._protocol = "5" if protocol is aiomqtt.ProtocolVersion.V5 else "3.1.1"
        return connection

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        connection, self._connection = self._connection, None
        self._protocol = None
        self._filters.clear()
        if connection is None:
            return
        taken = exc_type is not None and issubclass(exc_type, BaseTopicTakenError)
        # ``online`` said, or a state published before it (a stop takes that back too)
        said = self.announced or bool(self.retained_topics)
        if taken or not said:  # the will topic is another bridge's, or nothing was said
            self.announced = False
            await self._leave_quietly(connection)
            return
        self.announced = False
        stopping = exc_type is None or issubclass(exc_type, asyncio.CancelledError)
        try:
            if stopping:
                farewell = list(self.farewell()) if self.farewell is not None else []
                said = await self._say_farewell(connection, farewell)
            else:
                await connection.publish(self._will_topic, OFFLINE, 1, True, timeout=_CLOSE_TIMEOUT)
                said = True
            if said:  # else no DISCONNECT: it would drop the will, the only word left
                await connection.__aexit__(exc_type, exc, tb)
        except aiomqtt.MqttError as error:  # already lost: the broker publishes the will
            _log.debug("no clean MQTT disconnect: %s", error)
        finally:
            connection.abort()  # no-op after a clean DISCONNECT; else the will goes out

    async def _leave_quietly(self, connection: Connection) -> None:
        """Disconnect without a word: a clean DISCONNECT, so the broker drops the will too
        (another bridge's ``online`` stays)."""
        self._connection, self._protocol = None, None
        try:
            async with asyncio.timeout(_CLOSE_TIMEOUT):
                await connection.__aexit__(None, None, None)
        except (aiomqtt.MqttError, TimeoutError) as error:
            _log.debug("no clean MQTT disconnect: %s", error)
        finally:
            connection.abort()

    async def _say_farewell(self, connection: Connection, messages: list[tuple[str, str]]) -> bool:
        """The farewell messages and then the goodbye, sent at once and acknowledged
        together within FAREWELL_TIMEOUT seconds; False if the goodbye was not."""
        farewell: list[tuple[str, str | bytes]] = [*messages, (self._will_topic, self.goodbye)]
        try:
            async with asyncio.timeout(FAREWELL_TIMEOUT):
                results = await asyncio.gather(
                    *(connection.publish(t, p, 1, True, timeout=math.inf) for t, p in farewell),
                    return_exceptions=True,
                )
        except TimeoutError:
            _log.warning(
                "MQTT: the broker did not acknowledge the last %d messages within %gs; "
                "closing without DISCONNECT, so it publishes the will (offline)",
                len(farewell),
                FAREWELL_TIMEOUT,
            )
            return False
        failed = [r for r in results if isinstance(r, BaseException)]
        if failed:
            _log.debug("MQTT: %d of the last messages failed: %s", len(failed), failed[0])
        return not isinstance(results[-1], BaseException) and not connection.lost

    @property
    def unacknowledged(self) -> int:
        """Publishes handed to the broker and not acknowledged yet (0 when not connected)."""
        return self._connection.unacknowledged if self._connection is not None else 0

    def _require(self) -> Connection:
        if self._connection is None:
            raise MqttDisconnectedError("not connected")
        return self._connection

    async def publish(
        self, topic: str, payload: str | bytes, *, retain: bool = False, qos: int | None = None
    ) -> None:
        """Publish (at ``mqtt.qos`` unless given) and, for QoS 1/2, wait for the broker's
        acknowledgement."""
        await self._publish_all(((topic, payload, retain),), qos)

    async def publish_many(self, messages: Iterable[tuple[str, str | bytes, bool]]) -> None:
        """Publish (topic, payload, retain) messages all at once and wait for every
        acknowledgement together: a burst (the whole state after a reconnect) costs one
        round trip, not one per message. All of them are handed to the connection before
        anything else may publish: sent in parts, a later part could overtake a newer
        message on the same topic (an ``offline`` sent meanwhile, then the burst's
        ``online``). A message paho refuses (MqttPublishError) does not stop the others."""
        await self._publish_all(messages, None)

    async def _publish_all(
        self, messages: Iterable[tuple[str, str | bytes, bool]], qos: int | None
    ) -> None:
        """Hand every message to paho in order, then wait once for all acknowledgements
        (one event for the burst, not a task, an event and a timeout per message: issue 27);
        the first failure is raised once the others are acknowledged."""
        connection = self._require()
        level = self._config.qos if qos is None else qos
        acks = Acknowledgements()
        first: MqttError | None = None
        topic = ""
        for topic, payload, retain in messages:
            if retain and payload:
                self.retained_topics.add(topic)
            elif retain:
                self.retained_topics.discard(topic)
            try:
                connection.send(topic, payload, level, retain, acks)
            except aiomqtt.MqttError as exc:
                first = first or MqttDisconnectedError(f"publish to {topic[:200]}: {exc}")
            except ValueError as exc:  # paho: an invalid topic, a payload beyond 256 MB
                first = first or MqttPublishError(f"cannot publish to {topic[:200]}: {exc}")
        if first is not None and not acks.due:
            raise first
        sent = time.monotonic()
        try:
            await connection.acknowledged(acks)
        except aiomqtt.MqttError as exc:
            raise MqttDisconnectedError(f"publish to {topic[:200]}: {exc}") from exc
        restore_lost_cancel()
        if connection.lost:  # woken by the loss, not acknowledged
            raise MqttDisconnectedError(f"publish to {topic[:200]}: connection lost")
        if first is not None:
            raise first
        if acks.stalled > BACKLOG_SAID_AFTER and not connection.backlog_said:
            connection.backlog_said = True
            _log.warning(
                "MQTT: the broker is slower than the bridge: it acknowledged nothing for "
                "%.1f s; %d publishes took %.1f s in all, %d more wait for theirs; newer "
                "values replace the ones not sent yet (said once a session)",
                acks.stalled,
                len(acks.mids),
                time.monotonic() - sent,
                connection.unacknowledged,
            )

    async def subscribe(self, *filters: str, qos: int = 1, live_only: bool = False) -> None:
        """Subscribe to every filter in one SUBSCRIBE; MqttRefusedError if one is refused.

        ``live_only`` (command topics): on MQTT 5 the broker sends no retained message, keeps
        the retain flag of live ones and does not echo this client's own publishes; on
        3.1.1 the caller refuses retained messages.
        """
        connection = self._require()
        if not filters:
            return
        topics: list[tuple[str, int]] | list[tuple[str, SubscribeOptions]]
        topics = [(f, qos) for f in filters]
        if live_only and self._protocol == "5":
            options = SubscribeOptions(
                qos=qos,
                noLocal=True,  # not what this client publishes (an instance check)
                retainAsPublished=True,
                retainHandling=SubscribeOptions.RETAIN_DO_NOT_SEND,
            )
            topics = [(f, options) for f in filters]
        try:
            codes = await connection.subscribe(topics)
        except aiomqtt.MqttError as exc:
            if not connection.lost and "timed out" in str(exc):
                raise MqttUnackedError(
                    f"the broker did not acknowledge the subscription to {', '.join(filters)} "
                    f"within {connection.timeout:g} s"
                ) from None
            raise MqttDisconnectedError(f"subscribe to {', '.join(filters)}: {exc}") from exc
        restore_lost_cancel()
        if not isinstance(codes, list | tuple) or len(codes) != len(filters):
            raise MqttDisconnectedError(
                f"the broker answered a SUBSCRIBE of {len(filters)} filters with a SUBACK "
                "that does not match it; reconnecting"
            )
        refused = [f for f, code in zip(filters, codes, strict=True) if _value(code) >= FAILURE]
        if refused:
            raise MqttRefusedError(f"the broker refused the subscription to {', '.join(refused)}")
        self._filters.update(filters)

    async def messages(self) -> AsyncIterator[Message]:
        """Every message of the subscriptions, in arrival order, until the session ends."""
        iterator = self._require().messages
        while True:
            try:
                received = await anext(iterator)
            except aiomqtt.MqttError as exc:
                raise MqttDisconnectedError(
                    f"connection to {self._config.broker_url} lost: {exc}"
                ) from exc
            yield _message(received)

    async def retained(
        self,
        topic_filter: str,
        *,
        settle: float = 0.5,
        keep: Callable[[str], bool] | None = None,
        limit: int | None = None,
    ) -> dict[str, bytes]:
        """The retained messages under ``topic_filter`` now (topic -> payload), only those
        whose topic ``keep`` accepts if given (the others are not held in memory).

        Subscribes (at QoS 0: a retained message is read once, nothing to redeliver; on
        NATS a QoS 1 subscription is a JetStream consumer, which a cluster creates slowly
        after a node failure), collects until no retained message came for ``settle``
        seconds (or ``limit`` were kept: 1 for a single topic, whose message comes at once),
        then unsubscribes (unless ``subscribe()`` asked for the same filter). Live messages
        keep flowing to ``messages()`` meanwhile.
        """
        connection = self._require()
        kept = topic_filter in self._filters
        found: dict[str, bytes] = {}
        queue: asyncio.Queue[Received] = asyncio.Queue()
        connection.collectors[topic_filter] = queue
        try:
            await self.subscribe(topic_filter, qos=0)
            while True:
                try:  # asyncio.timeout, not wait_for: 3.11's wait_for can swallow a cancel
                    async with asyncio.timeout(settle):
                        received = await queue.get()
                except TimeoutError:
                    break
                if keep is None or keep(received.topic.value):
                    found[received.topic.value] = received.payload
                if limit is not None and len(found) >= limit:
                    break
            if not kept:
                await self._unsubscribe(connection, topic_filter)
        finally:
            del connection.collectors[topic_filter]
        while not queue.empty():  # arrived between the last wait and the UNSUBACK
            received = queue.get_nowait()
            if keep is None or keep(received.topic.value):
                found[received.topic.value] = received.payload
        return found

    @contextlib.asynccontextmanager
    async def watching(self, topic: str) -> AsyncIterator[Callable[[], Awaitable[Message]]]:
        """Every message on ``topic`` (one topic, no wildcard), retained or live, for the
        block's ``next()`` alone: ``messages()`` does not see them, nor they its own
        (subscribed at QoS 0, as ``retained``)."""
        connection = self._require()
        queue: asyncio.Queue[Received] = asyncio.Queue()
        connection.watchers[topic] = queue

        async def following() -> Message:
            return _message(await queue.get())

        try:
            await self.subscribe(topic, qos=0)
            yield following
            await self._unsubscribe(connection, topic)
        finally:
            del connection.watchers[topic]

    async def _unsubscribe(self, connection: Connection, topic_filter: str) -> None:
        try:
            await connection.unsubscribe(topic_filter)
        except aiomqtt.MqttError as exc:
            raise MqttDisconnectedError(f"unsubscribe from {topic_filter}: {exc}") from exc
        self._filters.discard(topic_filter)


def restore_lost_cancel() -> None:
    """Raise the cancellation that Python 3.11's ``asyncio.wait_for`` (used inside aiomqtt)
    swallows when the acknowledgement and the cancel arrive together; without this a
    stopping bridge could keep serving its MQTT session."""
    task = asyncio.current_task()
    if task is not None and task.cancelling():
        raise asyncio.CancelledError


def _value(code: int | Any) -> int:
    return code if isinstance(code, int) else int(code.value)


def _message(received: aiomqtt.Message) -> Message:
    expiry = getattr(received.properties, "MessageExpiryInterval", None)
    return Message(
        topic=received.topic.value,
        payload=bytes(received.payload),
        qos=received.qos,
        retain=bool(received.retain),
        duplicate=isinstance(received, Received) and received.duplicate,
        mid=received.mid if received.qos > 0 else None,
        expiry=float(expiry) if isinstance(expiry, int) else None,
        received=received.received if isinstance(received, Received) else None,
    )
