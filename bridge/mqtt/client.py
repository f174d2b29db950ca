"""The MQTT edge: the only module that imports aiomqtt (and through it paho-mqtt).

``MqttClient`` is one broker session as an async context manager: entering connects
(mqtt:// or mqtts://, user name and password, MQTT 5 with a fallback to 3.1.1 when the
broker refuses 5 or takes the connection but never answers an MQTT 5 CONNECT, as amqtt
does), sets the Last Will ``offline`` (retained, QoS 1) on the will topic and
publishes ``online`` there; leaving cleanly (the session returned or was cancelled: a
stop) publishes the caller's ``farewell`` messages (retained: devices going offline, or
empty payloads that remove what the session published, ``retained_topics``), then
``goodbye`` on the will topic (``offline``; empty removes it), all at once, and disconnects
once the broker acknowledged them all; if it did not within ``FAREWELL_TIMEOUT`` seconds,
the socket is closed without DISCONNECT, so the broker publishes the will. Incoming
messages are ``Message`` values, decoupled from paho. The caller owns the reconnect loop;
``run_with_reconnect`` is that loop, with a capped exponential backoff; once a broker
needed the fallback, its reconnects ask for 3.1.1 at once.

aiomqtt 2.5 drops paho's DUP flag when it wraps a message, so ``_Connection`` overrides
aiomqtt's (private) ``_on_message`` hook to keep it; the pinned minor keeps that stable
and tests/integration/test_mqtt_client.py checks it against a broker that sets DUP.
aiomqtt also ignores the reason code of an MQTT 5 PUBACK; ``_Connection`` overrides
``_on_publish`` so that a publish the broker refuses (an ACL: 0x87 not authorised) is
logged once per topic at WARNING instead of passing for delivered.

Safety on MQTT 5: ``subscribe(..., live_only=True)`` asks the broker not to send retained
messages at all (retain handling 2) and to keep the retain flag of live ones (retain as
published), so the caller can refuse a command published with retain; the CONNECT
announces ``MAX_PACKET`` as the largest packet the bridge accepts (the broker drops
bigger ones instead of sending them); ``Message.expiry`` carries the publisher's message
expiry interval (the time it has left).

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

Anything a broker answers that the protocol does not allow (a SUBACK with the wrong
number of codes, a packet paho cannot parse) ends the session with
MqttDisconnectedError, so the reconnect loop starts a new one; it never ends the process.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
import secrets
import socket
import ssl
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Self
from urllib.parse import urlsplit

import aiomqtt
import paho.mqtt.client as paho
from aiomqtt.exceptions import MqttConnectError as _RefusedByBroker
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.reasoncodes import ReasonCode
from paho.mqtt.subscribeoptions import SubscribeOptions

from bridge.config import MqttConfig, TlsConfig
from bridge.core.backoff import BrokerUrls, ReconnectBackoff
from bridge.mqtt.errors import (
    BaseTopicTakenError,
    MqttConnectError,
    MqttDisconnectedError,
    MqttPublishError,
    MqttRefusedError,
    MqttUnackedError,
    MqttUnansweredError,
)

ONLINE = b"online"
OFFLINE = b"offline"
_UNSUPPORTED_PROTOCOL_VERSION = 0x84  # CONNACK reason code (3.1.1 return code 1 maps to it)
_TIMEOUT = 10.0  # seconds for CONNACK, PUBACK, SUBACK, UNSUBACK
_CLOSE_TIMEOUT = 2.0  # the goodbye "offline" must not hold up a shutdown
FAREWELL_TIMEOUT = 2.0  # seconds for the farewell messages and the goodbye: a stop ends in 3 s
_FAILURE = 0x80  # SUBACK/PUBACK reason codes from 0x80 up are failures
MAX_PACKET = 4 * 1024 * 1024  # bytes: MQTT 5 brokers drop larger packets for the bridge
STANDBY_RETRY = 10.0  # seconds between two looks at a base topic another bridge serves
BACKLOG_SAID_AFTER = 30.0  # seconds a PUBACK took: the broker is slower than the bridge

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


class _Received(aiomqtt.Message):
    """aiomqtt's message plus the DUP flag that aiomqtt leaves out."""

    def __init__(self, message: paho.MQTTMessage) -> None:
        properties = getattr(message, "properties", None)
        super().__init__(
            message.topic,
            bytes(message.payload),
            message.qos,
            message.retain,
            message.mid,
            properties,
        )
        self.duplicate = bool(message.dup)
        self.received = time.monotonic()


class _Connection(aiomqtt.Client):
    """aiomqtt's client, keeping DUP and routing retained messages to ``retained()``."""

    def __init__(self, hostname: str, port: int, **options: Any) -> None:
        super().__init__(hostname, port, **options)
        # aiomqtt warns for every publish beyond ten unacknowledged ones: a burst of state
        # is normal operation; a backlog is said by MqttClient.publish, once, with numbers
        self.pending_calls_threshold = 2**62
        self.backlog_said = False
        self.collectors: dict[str, asyncio.Queue[_Received]] = {}
        self.watchers: dict[str, asyncio.Queue[_Received]] = {}  # by exact topic, live too
        self.refused_topics: set[str] = set()  # publishes the broker refused (logged once)
        self.reached = False  # the socket (and TLS) connected and CONNECT was sent

    def _on_socket_open(self, client: paho.Client, userdata: Any, sock: Any) -> None:
        """The socket (and TLS) connected; paho sends the CONNECT next. Marked here, in the
        connecting thread before the CONNECT goes out, not once connect() returned: a
        broker that closes at once on the CONNECT (RabbitMQ 3.x and MQTT 5) could be read
        on the event loop before that, and was taken for a refused connection."""
        self.reached = True
        super()._on_socket_open(client, userdata, sock)

    def _on_disconnect(self, *args: Any, **kwargs: Any) -> None:
        """A broker that closes the connection instead of answering the CONNECT (RabbitMQ
        3.x does for MQTT 5) ends the wait at once; aiomqtt would wait out the timeout."""
        if self.reached and not self._connected.done():
            self._connected.set_exception(aiomqtt.MqttError("closed before CONNACK"))
            return
        super()._on_disconnect(*args, **kwargs)

    def _on_publish(
        self,
        client: paho.Client,
        userdata: Any,
        mid: int,
        reason_code: ReasonCode,
        properties: Properties,
    ) -> None:
        if isinstance(reason_code, ReasonCode) and reason_code.value >= _FAILURE:
            message = self._client._out_messages.get(mid)
            topic = message.topic if message is not None else f"message {mid}"
            level = logging.DEBUG if topic in self.refused_topics else logging.WARNING
            self.refused_topics.add(topic)
            _log.log(level, "the broker refused a publish to %s: %s", topic, reason_code)
        super()._on_publish(client, userdata, mid, reason_code, properties)

    def _on_subscribe(self, client: paho.Client, userdata: Any, mid: int, *args: Any) -> None:
        """aiomqtt's, except that the SUBACK of a SUBSCRIBE given up on (no answer in time:
        a cluster creating its consumers) is a DEBUG line, not an ERROR with a traceback."""
        if mid not in self._pending_subscribes:
            _log.debug("a late SUBACK (message %d): the subscription was asked again", mid)
            return
        super()._on_subscribe(client, userdata, mid, *args)

    def _on_unsubscribe(self, client: paho.Client, userdata: Any, mid: int, *args: Any) -> None:
        if mid not in self._pending_unsubscribes:
            _log.debug("a late UNSUBACK (message %d)", mid)
            return
        super()._on_unsubscribe(client, userdata, mid, *args)

    def _on_message(self, _client: paho.Client, _userdata: Any, message: paho.MQTTMessage) -> None:
        received = _Received(message)
        watcher = self.watchers.get(received.topic.value)
        if watcher is not None:
            watcher.put_nowait(received)
            return
        if received.retain:
            for topic_filter, queue in self.collectors.items():
                if received.topic.matches(topic_filter):
                    queue.put_nowait(received)
                    return
        self._queue.put_nowait(received)  # unbounded: never QueueFull

    def _on_socket_register_write(self, client: paho.Client, _userdata: Any, sock: Any) -> None:
        """aiomqtt's, except that a socket closed before the loop's next turn is skipped:
        aiomqtt's deferred ``add_writer`` on a closed descriptor made asyncio log a
        traceback whenever a connection broke while the bridge was sending."""
        fileno = sock.fileno()

        def write() -> None:
            try:
                client.loop_write()
            except OSError as exc:  # the connection broke: the session ends
                if not self._disconnected.done():
                    self._disconnected.set_exception(exc)

        def register() -> None:
            if sock.fileno() == fileno:  # else closed meanwhile: nothing to write to
                self._loop.add_writer(fileno, write)

        self._loop.call_soon_threadsafe(register)

    def abort(self) -> None:
        """Close a connection that never completed; paho's close also stops aiomqtt's tasks."""
        self._client._sock_close()

    @property
    def lost(self) -> bool:
        """The broker connection ended (the socket closed, paho gave up on keepalive)."""
        return self._disconnected.done()

    def wake_on_loss(self) -> None:
        """When the connection ends, wake whatever waits for an acknowledgement at once:
        aiomqtt would leave it waiting for its whole timeout (10 s) after a broker died."""

        def wake(lost: asyncio.Future[None]) -> None:
            if not lost.cancelled():
                lost.exception()  # seen: asyncio would log it as never retrieved
            for event in (*self._pending_publishes.values(), *self._pending_unsubscribes.values()):
                event.set()
            for future in self._pending_subscribes.values():
                if not future.done():
                    future.set_exception(aiomqtt.MqttError("connection lost"))

        self._disconnected.add_done_callback(wake)


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
        self._will_topic = will_topic
        self._client_id = client_id if client_id is not None else config.client_id
        self._connection: _Connection | None = None
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
            context = await asyncio.to_thread(_tls_context, self._config)
        except (OSError, ssl.SSLError) as exc:
            raise MqttConnectError(f"{url}: cannot load TLS files: {exc}") from exc
        if self._version == "5":
            try:
                connection = await self._open(aiomqtt.ProtocolVersion.V5, context)
            except MqttConnectError as exc:
                if isinstance(exc, MqttUnansweredError):
                    _log.info("%s does not answer an MQTT 5 CONNECT; trying 3.1.1", url)
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
    ) -> _Connection:
        config = self._config
        try:
            password = config.password_value()
        except OSError as exc:
            raise MqttConnectError(
                f"{config.broker_url}: cannot read the password: {exc.strerror}"
            ) from exc
        limits = None
        v5 = protocol is aiomqtt.ProtocolVersion.V5
        if v5:
            limits = Properties(PacketTypes.CONNECT)  # type: ignore[no-untyped-call]
            limits.MaximumPacketSize = MAX_PACKET
            limits.SessionExpiryInterval = 0  # the session ends with the connection
        connection = _Connection(
            config.host,
            config.port,
            properties=limits,
            identifier=self._client_id,
            # nothing kept between sessions: clean start (5), clean session (3.1.1)
            clean_session=None if v5 else True,
            clean_start=True if v5 else paho.MQTT_CLEAN_START_FIRST_ONLY,
            username=config.username,
            password=password,
            protocol=protocol,
            will=aiomqtt.Will(self._will_topic, OFFLINE, qos=1, retain=True),
            keepalive=round(config.keepalive),
            tls_context=context,
            timeout=_TIMEOUT,
            logger=_log.getChild("paho"),
        )
        try:
            await connection.__aenter__()
        except BaseException as exc:  # also cancelled: aiomqtt leaves the socket open
            connection.abort()
            if isinstance(exc, _RefusedByBroker):
                code = exc.rc if isinstance(exc.rc, int) or exc.rc is None else exc.rc.value
                raise MqttConnectError(
                    f"{config.broker_url} refused the connection: {exc}", code
                ) from exc
            if isinstance(exc, aiomqtt.MqttError) and connection.reached:
                raise MqttUnansweredError(
                    f"{config.broker_url} took the connection but did not answer the CONNECT: {exc}"
                ) from exc
            if isinstance(exc, aiomqtt.MqttError):
                raise MqttConnectError(f"cannot connect to {config.broker_url}: {exc}") from exc
            raise
        _send_at_once(connection)
        connection.wake_on_loss()
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
        if taken or not self.announced:  # the will topic is another bridge's, or not said
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

    async def _leave_quietly(self, connection: _Connection) -> None:
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

    async def _say_farewell(self, connection: _Connection, messages: list[tuple[str, str]]) -> bool:
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

    def _require(self) -> _Connection:
        if self._connection is None:
            raise MqttDisconnectedError("not connected")
        return self._connection

    async def publish(
        self, topic: str, payload: str | bytes, *, retain: bool = False, qos: int | None = None
    ) -> None:
        """Publish (at ``mqtt.qos`` unless given) and, for QoS 1/2, wait for the broker's
        acknowledgement."""
        connection = self._require()
        level = self._config.qos if qos is None else qos
        if retain and payload:
            self.retained_topics.add(topic)
        elif retain:
            self.retained_topics.discard(topic)
        sent = time.monotonic()
        try:
            await connection.publish(topic, payload, level, retain)
        except aiomqtt.MqttError as exc:
            raise MqttDisconnectedError(f"publish to {topic[:200]}: {exc}") from exc
        except ValueError as exc:  # paho: an invalid topic, a payload beyond 256 MB
            raise MqttPublishError(f"cannot publish to {topic[:200]}: {exc}") from None
        _restore_lost_cancel()
        if connection.lost:  # woken by the loss, not acknowledged
            raise MqttDisconnectedError(f"publish to {topic[:200]}: connection lost")
        waited = time.monotonic() - sent
        if waited > BACKLOG_SAID_AFTER and not connection.backlog_said:
            connection.backlog_said = True
            _log.warning(
                "MQTT: the broker is slower than the bridge: an acknowledgement took %.0f s, "
                "%d publishes wait for theirs (said once a session)",
                waited,
                len(connection._pending_publishes),
            )

    async def publish_many(self, messages: Iterable[tuple[str, str | bytes, bool]]) -> None:
        """Publish (topic, payload, retain) messages all at once and wait for every
        acknowledgement together: a burst (the whole state after a reconnect) costs one
        round trip, not one per message. All of them are handed to the connection before
        anything else may publish: sent in parts, a later part could overtake a newer
        message on the same topic (an ``offline`` sent meanwhile, then the burst's
        ``online``)."""
        # gather, not a TaskGroup: on Python 3.11 a TaskGroup whose task fails while it
        # waits leaves its parent task marked as cancelling for good (fixed in 3.12), and
        # the reconnect loop must go on after a lost connection
        results = await asyncio.gather(
            *(self.publish(topic, payload, retain=retain) for topic, payload, retain in messages),
            return_exceptions=True,
        )
        for result in results:
            if isinstance(result, BaseException):
                raise result

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
                    f"within {_TIMEOUT:g} s"
                ) from None
            raise MqttDisconnectedError(f"subscribe to {', '.join(filters)}: {exc}") from exc
        _restore_lost_cancel()
        if not isinstance(codes, list | tuple) or len(codes) != len(filters):
            raise MqttDisconnectedError(
                f"the broker answered a SUBSCRIBE of {len(filters)} filters with a SUBACK "
                "that does not match it; reconnecting"
            )
        refused = [f for f, code in zip(filters, codes, strict=True) if _value(code) >= _FAILURE]
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

        Subscribes, collects until no retained message came for ``settle`` seconds (or
        ``limit`` were kept: 1 for a single topic, whose message comes at once), then
        unsubscribes (unless ``subscribe()`` asked for the same filter). Live messages
        keep flowing to ``messages()`` meanwhile.
        """
        connection = self._require()
        kept = topic_filter in self._filters
        found: dict[str, bytes] = {}
        queue: asyncio.Queue[_Received] = asyncio.Queue()
        connection.collectors[topic_filter] = queue
        try:
            await self.subscribe(topic_filter)
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
        block's ``next()`` alone: ``messages()`` does not see them, nor they its own."""
        connection = self._require()
        queue: asyncio.Queue[_Received] = asyncio.Queue()
        connection.watchers[topic] = queue

        async def following() -> Message:
            return _message(await queue.get())

        try:
            await self.subscribe(topic)
            yield following
            await self._unsubscribe(connection, topic)
        finally:
            del connection.watchers[topic]

    async def _unsubscribe(self, connection: _Connection, topic_filter: str) -> None:
        try:
            await connection.unsubscribe(topic_filter)
        except aiomqtt.MqttError as exc:
            raise MqttDisconnectedError(f"unsubscribe from {topic_filter}: {exc}") from exc
        self._filters.discard(topic_filter)


def run_client_id() -> str:
    """A client id for one run of the bridge: ``modbusbridge`` and 10 random hex digits
    (22 characters from MQTT 3.1.1's safe set: every broker takes it)."""
    return f"modbusbridge{secrets.token_hex(5)}"


def _send_at_once(connection: _Connection) -> None:
    """TCP_NODELAY on the session's socket. paho leaves Nagle's algorithm on, which holds a
    small publish (the state after a command) until the broker acknowledges the previous
    segment, up to 40 ms on Linux (bench/latency.py)."""
    sock = connection._client.socket()
    if isinstance(sock, socket.socket):  # ssl.SSLSocket included
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


def _restore_lost_cancel() -> None:
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
        duplicate=isinstance(received, _Received) and received.duplicate,
        mid=received.mid if received.qos > 0 else None,
        expiry=float(expiry) if isinstance(expiry, int) else None,
        received=received.received if isinstance(received, _Received) else None,
    )


class _ClosingSSLSocket(ssl.SSLSocket):
    """paho leaves the socket open when the TLS handshake fails; close it right there."""

    def do_handshake(self, block: bool = False) -> None:
        try:
            super().do_handshake(block)
        except BaseException:
            self.close()
            raise


def _tls_context(config: MqttConfig) -> ssl.SSLContext | None:
    """The TLS context for mqtts:// (None for mqtt://); reads the CA and key files."""
    if urlsplit(config.broker_url).scheme != "mqtts":
        return None
    tls = config.tls or TlsConfig()
    context = ssl.create_default_context(cafile=tls.ca)
    context.sslsocket_class = _ClosingSSLSocket
    if tls.cert is not None:
        context.load_cert_chain(tls.cert, tls.key)
    if tls.insecure:
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
    return context


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
                loop.version = client.protocol
                loop.connected = loop.ever_connected = True
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
        _restore_lost_cancel()
        await asyncio.sleep(loop.standby(taken) if taken is not None else loop.down(failure, url))


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
        self.outage: str | None = None
        self.standing_by = False
        self.connected = False  # this attempt's session started
        self.ever_connected = False

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
