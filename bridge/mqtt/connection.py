"""One connection to a broker through aiomqtt (and paho-mqtt under it): what a session
(bridge/mqtt/session.py) stands on, and the only module that reaches into aiomqtt's and
paho's internals (the pinned minor keeps them stable).

``connect`` opens one connection at one protocol version: TLS for mqtts:// (a failed
handshake closes its socket right there), user name and password, the Last Will
``offline`` (retained, QoS 1) on the will topic, a clean start (3.1.1: clean session) and,
on MQTT 5, a session expiry of 0 and ``MAX_PACKET`` as the largest packet the bridge
accepts (the broker drops bigger ones instead of sending them). It tells a refusal
(MqttConnectError with the broker's code), a connection taken but never answered
(MqttUnansweredError: the session falls back to 3.1.1) and a broker out of reach apart.
``TIMEOUT`` bounds every wait for an answer: CONNACK, PUBACK, SUBACK, UNSUBACK (a PUBACK
wait ends only when the broker acknowledged no publish at all for that long). The socket
sends at once (TCP_NODELAY).

``Connection`` is aiomqtt's client with paho's callbacks overridden:

- aiomqtt 2.5 drops paho's DUP flag when it wraps a message; ``Received`` keeps it
  (tests/integration/test_mqtt_client.py checks it against a broker that sets DUP);
- aiomqtt ignores the reason code of an MQTT 5 PUBACK: a publish the broker refuses (an
  ACL: 0x87 not authorised) is logged once per topic at WARNING instead of passing for
  delivered;
- retained messages matching a filter in ``collectors`` go there, every message on a topic
  in ``watchers`` goes there, the rest to the session's ``messages()``;
- ``send`` hands a publish to paho and ``acknowledged`` waits for a whole burst's
  acknowledgements at once (``Acknowledgements``: one event, counted down by aiomqtt's
  ``_on_publish``), in place of aiomqtt's ``publish``: its task, event, ``wait_for`` and
  two scans of every pending call per message cost as much CPU as paho itself
  (bench/floor.py, issue 27);
- a broker that closes the connection instead of answering the CONNECT ends the wait at
  once; a SUBACK or UNSUBACK given up on is a DEBUG line; a socket closed before asyncio
  registers its writer is skipped; ``wake_on_loss`` wakes every wait for an
  acknowledgement as soon as the connection ends.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import ssl
import time
from collections import deque
from typing import Any, Literal
from urllib.parse import urlsplit

import aiomqtt
import paho.mqtt.client as paho
from aiomqtt.exceptions import MqttConnectError as _RefusedByBroker
from paho.mqtt.client import DISCONNECT, PUBLISH
from paho.mqtt.enums import MQTTErrorCode
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.reasoncodes import ReasonCode

from bridge.config import MqttConfig, TlsConfig
from bridge.mqtt.errors import MqttConnectError, MqttUnansweredError

OFFLINE = b"offline"
TIMEOUT = 10.0  # seconds for CONNACK, PUBACK, SUBACK, UNSUBACK
FAILURE = 0x80  # SUBACK/PUBACK reason codes from 0x80 up are failures
MAX_PACKET = 4 * 1024 * 1024  # bytes: MQTT 5 brokers drop larger packets for the bridge

_log = logging.getLogger(__name__)
_PLAIN_ACKS = {  # PUBACK reason codes told with a shared value: success, no subscribers
    code: ReasonCode(PacketTypes.PUBACK, identifier=code) for code in (0x00, 0x10)
}
_NO_PROPERTIES = Properties(PacketTypes.PUBACK)  # type: ignore[no-untyped-call]


class Received(aiomqtt.Message):
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


class Acknowledgements(asyncio.Event):
    """The acknowledgements a burst of publishes waits for, as one event: it stands in
    aiomqtt's ``_pending_publishes`` for each message, whose ``_on_publish`` (and
    ``wake_on_loss``) call ``set()`` once per message; it is set when none is due.
    ``stalled`` is the longest the broker acknowledged none of them (from ``start()``)."""

    def __init__(self) -> None:
        super().__init__()
        self.mids: list[int] = []
        self.due = 0
        self.stalled = 0.0
        self._last = 0.0

    def start(self) -> None:
        """The burst is handed over: the broker's time begins."""
        self._last = time.monotonic()

    def set(self) -> None:
        self.due -= 1
        now = time.monotonic()
        self.stalled = max(self.stalled, now - self._last)
        self._last = now
        if self.due <= 0:
            super().set()


class Connection(aiomqtt.Client):
    """aiomqtt's client, keeping DUP and routing retained messages to ``retained()``."""

    def __init__(self, hostname: str, port: int, **options: Any) -> None:
        super().__init__(hostname, port, **options)
        # aiomqtt warns for every publish beyond ten unacknowledged ones: a burst of state
        # is normal operation; a backlog is said by MqttClient.publish, once, with numbers
        self.pending_calls_threshold = 2**62
        self.backlog_said = False
        self.collectors: dict[str, asyncio.Queue[Received]] = {}
        self.watchers: dict[str, asyncio.Queue[Received]] = {}  # by exact topic, live too
        self.refused_topics: set[str] = set()  # publishes the broker refused (logged once)
        self.reached = False  # the socket (and TLS) connected and CONNECT was sent
        self.last_acknowledgement = 0.0  # monotonic time of the broker's latest PUBACK/PUBCOMP
        self._client._handle_pubackcomp = self._acknowledgement  # type: ignore[method-assign,assignment]

    def _acknowledgement(self, kind: Literal["PUBACK", "PUBCOMP"]) -> MQTTErrorCode:
        """paho's PUBACK/PUBCOMP handling, but a PUBACK without properties that says
        success or no matching subscribers (what brokers send for nearly every publish: the
        packet identifier, on MQTT 5 perhaps with the reason code) is told to
        ``on_publish`` with a shared reason code and no properties instead of two reason
        codes and a properties object made for each (issue 27)."""
        client = self._client
        packet = client._in_packet["packet"]
        if kind != "PUBACK" or len(packet) not in (2, 3):
            return paho.Client._handle_pubackcomp(client, kind)
        reason = _PLAIN_ACKS.get(packet[2] if len(packet) == 3 else 0)
        if reason is None or (len(packet) == 3 and client._protocol != paho.MQTTv5):
            return paho.Client._handle_pubackcomp(client, kind)
        mid = int.from_bytes(packet[:2], "big")
        with client._out_message_mutex:
            if mid in client._out_messages:
                return client._do_on_publish(mid, reason, _NO_PROPERTIES)
        return MQTTErrorCode.MQTT_ERR_SUCCESS

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
        if isinstance(reason_code, ReasonCode) and reason_code.value >= FAILURE:
            message = self._client._out_messages.get(mid)
            topic = message.topic if message is not None else f"message {mid}"
            level = logging.DEBUG if topic in self.refused_topics else logging.WARNING
            self.refused_topics.add(topic)
            _log.log(level, "the broker refused a publish to %s: %s", topic, reason_code)
        self.last_acknowledgement = time.monotonic()
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
        received = Received(message)
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
                coalesce(client._out_packet)
                client.loop_write()
            except OSError as exc:  # the connection broke: the session ends
                if not self._disconnected.done():
                    self._disconnected.set_exception(exc)

        def register() -> None:
            if sock.fileno() == fileno:  # else closed meanwhile: nothing to write to
                self._loop.add_writer(fileno, write)

        self._loop.call_soon_threadsafe(register)

    def send(
        self, topic: str, payload: str | bytes, qos: int, retain: bool, acks: Acknowledgements
    ) -> None:
        """Hand one publish to paho; ``acks`` waits for it. ValueError for what paho
        refuses (an invalid topic, a payload beyond 256 MB), aiomqtt.MqttCodeError when it
        cannot be queued (not connected)."""
        info = self._client.publish(topic, payload, qos, retain)
        if info.rc != paho.MQTT_ERR_SUCCESS:
            raise aiomqtt.MqttCodeError(info.rc, "Could not publish message")
        if not info.is_published():
            self._pending_publishes[info.mid] = acks
            acks.mids.append(info.mid)
            acks.due += 1

    async def acknowledged(self, acks: Acknowledgements) -> None:
        """Wait until the broker acknowledged every publish of ``acks`` (or the connection
        was lost); aiomqtt.MqttError if it acknowledged nothing at all, of any publish on
        this connection, for ``TIMEOUT`` seconds. A broker that keeps acknowledging, however
        slowly (paho keeps 20 publishes in flight), is waited for: a long burst to a slow
        broker is no lost connection, nor is a publish queued behind such a burst."""
        try:
            acks.start()
            while acks.due > 0 and not self.lost:  # else woken already, or never
                waited = time.monotonic()
                try:
                    async with asyncio.timeout(self.timeout):
                        await acks.wait()
                except TimeoutError:
                    if self.last_acknowledgement < waited:  # not one in all that time
                        raise aiomqtt.MqttError("Operation timed out") from None
        finally:
            for mid in acks.mids:  # acknowledged ones are gone already
                if self._pending_publishes.get(mid) is acks:
                    del self._pending_publishes[mid]

    def send_at_once(self) -> None:
        """TCP_NODELAY on the socket. paho leaves Nagle's algorithm on, which holds a small
        publish (the state after a command) until the broker acknowledges the previous
        segment, up to 40 ms on Linux (bench/latency.py)."""
        sock = self._client.socket()
        if isinstance(sock, socket.socket):  # ssl.SSLSocket included
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    @property
    def unacknowledged(self) -> int:
        """Publishes waiting for the broker's acknowledgement."""
        return len(self._pending_publishes)

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


def coalesce(queue: deque[Any]) -> None:
    """Join the packets at the head of paho's out queue that need nothing done once
    written (every packet but a QoS 0 PUBLISH, whose ``on_publish`` paho calls then, and
    DISCONNECT, after which it closes) into one, so that one ``send()`` carries a burst:
    paho sends each packet on its own, a system call and a TCP segment per message."""
    count = 0
    for packet in queue:
        if not _inert(packet):
            break
        count += 1
    if count < 2:
        return
    parts = []
    for _ in range(count):
        packet = queue.popleft()
        parts.append(bytes(packet["packet"][packet["pos"] :]))
    joined = b"".join(parts)
    # command 0 (reserved): paho's _packet_write has nothing to do once it is written
    joined_packet = {"command": 0, "mid": 0, "qos": 0, "pos": 0, "info": None}
    queue.appendleft(joined_packet | {"to_process": len(joined), "packet": joined})


def _inert(packet: dict[str, Any]) -> bool:
    kind = packet["command"] & 0xF0
    return not (kind == PUBLISH and packet["qos"] == 0) and kind != DISCONNECT


async def connect(
    config: MqttConfig,
    protocol: aiomqtt.ProtocolVersion,
    context: ssl.SSLContext | None,
    *,
    client_id: str | None,
    will_topic: str | None,
) -> Connection:
    """One connection at ``protocol``, connected (CONNACK received), or MqttConnectError;
    with no ``will_topic`` no Last Will (a probe)."""
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
    connection = Connection(
        config.host,
        config.port,
        properties=limits,
        identifier=client_id,
        # nothing kept between sessions: clean start (5), clean session (3.1.1)
        clean_session=None if v5 else True,
        clean_start=True if v5 else paho.MQTT_CLEAN_START_FIRST_ONLY,
        username=config.username,
        password=password,
        protocol=protocol,
        will=None if will_topic is None else aiomqtt.Will(will_topic, OFFLINE, qos=1, retain=True),
        keepalive=round(config.keepalive),
        tls_context=context,
        timeout=TIMEOUT,
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
    connection.send_at_once()
    connection.wake_on_loss()
    return connection


class _ClosingSSLSocket(ssl.SSLSocket):
    """paho leaves the socket open when the TLS handshake fails; close it right there."""

    def do_handshake(self, block: bool = False) -> None:
        try:
            super().do_handshake(block)
        except BaseException:
            self.close()
            raise


def tls_context(config: MqttConfig) -> ssl.SSLContext | None:
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
