"""bridge.mqtt against a real mosquitto, and a byte-level stub broker for what mosquitto
won't do (answer with DUP set, never answer an MQTT 5 CONNECT like amqtt, close on it like
RabbitMQ 3.x, die before a PUBACK). The stub plays the broker, the peer; the client under
test is the real bridge.mqtt over a real socket. Where a test shortens the client's own
CONNACK timeout (``_TIMEOUT``), it is to keep the test short, not to replace anything."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import time
from collections.abc import AsyncIterator, Awaitable
from pathlib import Path
from typing import Any, TypeVar

import pytest

from bridge.config import MqttConfig, TlsConfig
from bridge.core.backoff import ReconnectBackoff
from bridge.mqtt import (
    Message,
    MqttClient,
    MqttConnectError,
    MqttDisconnectedError,
    MqttUnansweredError,
    run_with_reconnect,
)
from bridge.mqtt import connection as connection_module
from bridge.mqtt import reconnect as reconnect_module
from tests.conftest import BROKER_PASSWORD, BROKER_USER
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker, TlsFiles
from tests.ports import free_port

STATE = "t/bridge/state"
T = TypeVar("T")


def cfg(url: str, **fields: Any) -> MqttConfig:
    return MqttConfig(url=url, keepalive=5, **fields)


async def within(awaitable: Awaitable[T], seconds: float = 5) -> T:
    return await asyncio.wait_for(awaitable, seconds)


async def next_message(client: MqttClient) -> Message:
    return await within(anext(aiter(client.messages())))


@contextlib.asynccontextmanager
async def watcher(url: str, *filters: str) -> AsyncIterator[MqttClient]:
    """A second client, subscribed to ``filters``."""
    async with MqttClient(cfg(url), will_topic="t/watcher/state") as client:
        await client.subscribe(*filters)
        yield client


# -- sessions ------------------------------------------------------------------------


@pytest.mark.asyncio
@pytest.mark.parametrize("version", ["5", "3.1.1"])
async def test_publish_subscribe_round_trip(mosquitto: Broker, version: str) -> None:
    async with MqttClient(cfg(mosquitto.url, version=version), will_topic=STATE) as client:
        assert client.protocol == version
        await client.subscribe("t/in/#", "t/other")
        async with watcher(mosquitto.url) as other:
            sent = time.monotonic()
            await other.publish("t/in/x", "hello")
        message = await next_message(client)
    assert message.received is not None and sent <= message.received <= time.monotonic()
    assert (message.topic, message.payload, message.qos, message.retain) == (
        "t/in/x",
        b"hello",
        1,
        False,
    )
    assert message.duplicate is False
    assert isinstance(message.mid, int)


@pytest.mark.asyncio
@pytest.mark.parametrize("qos", [0, 2])
async def test_publishes_use_the_configured_qos(mosquitto: Broker, qos: int) -> None:
    """``mqtt.qos`` applies to what the bridge publishes (received at min(pub, sub) QoS)."""
    async with MqttClient(cfg(mosquitto.url), will_topic=STATE) as client:
        await client.subscribe("t/q", qos=2)
        async with MqttClient(cfg(mosquitto.url, qos=qos), will_topic="t/p/state") as other:
            await other.publish("t/q", "x")
        message = await next_message(client)
    assert message.qos == qos


@pytest.mark.asyncio
async def test_online_while_connected_offline_after_a_clean_exit(mosquitto: Broker) -> None:
    async with MqttClient(cfg(mosquitto.url), will_topic=STATE), watcher(mosquitto.url) as other:
        assert await other.retained(STATE, settle=0.2) == {STATE: b"online"}
    async with watcher(mosquitto.url) as other:
        assert await other.retained(STATE, settle=0.2) == {STATE: b"offline"}


def nodelay(client: MqttClient) -> int:
    sock = client._connection._client.socket()  # type: ignore[union-attr]
    return sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)  # type: ignore[union-attr]


@pytest.mark.asyncio
async def test_messages_leave_at_once_without_nagle(mosquitto: Broker) -> None:
    async with MqttClient(cfg(mosquitto.url), will_topic=STATE) as client:
        assert nodelay(client)


@pytest.mark.asyncio
async def test_last_will_when_the_connection_dies(mosquitto: Broker) -> None:
    async with (
        MqttClient(cfg(mosquitto.url), will_topic=STATE) as client,
        watcher(mosquitto.url, STATE) as other,
    ):
        assert (await next_message(other)).payload == b"online"
        # Cut the TCP connection under paho: no DISCONNECT is sent, so the broker
        # publishes the will while ``client`` is still inside its context.
        client._connection._client.socket().shutdown(socket.SHUT_RDWR)  # type: ignore[union-attr]
        will = await next_message(other)
        assert (will.topic, will.payload) == (STATE, b"offline")
        with pytest.raises(MqttDisconnectedError):
            await within(anext(aiter(client.messages())))
        with pytest.raises(MqttDisconnectedError):
            await client.publish("t/x", "lost")


@pytest.mark.asyncio
async def test_a_burst_longer_than_one_chunk_arrives_whole(mosquitto: Broker) -> None:
    """Every message of a burst longer than paho's in-flight window (20) arrives, and the
    call returns when the last is acknowledged."""
    count = 207
    burst = [(f"t/burst/{i}", str(i), True) for i in range(count)]
    async with MqttClient(cfg(mosquitto.url), will_topic=STATE) as client:
        await client.publish_many(burst)
        found = await client.retained("t/burst/+", settle=0.5)
    assert found == {topic: payload.encode() for topic, payload, _ in burst}


@pytest.mark.asyncio
@pytest.mark.parametrize("version", ["5", "3.1.1"])
async def test_a_burst_reaches_a_subscriber_whole_and_in_order(
    mosquitto: Broker, version: str
) -> None:
    """The packets of a burst go out joined (one send for what paho queued, issue 27) and
    their PUBACKs (reason code 0 with a subscriber) are taken on a short path: every
    message arrives once, byte for byte and in order, and the call returns acknowledged."""
    count = 300
    burst = [("t/order", f"{i}:" + "x" * (i % 37), i % 2 == 0) for i in range(count)]
    async with (
        watcher(mosquitto.url, "t/order") as other,
        MqttClient(cfg(mosquitto.url, version=version), will_topic=STATE) as client,
    ):
        await client.publish_many(burst)
        seen = [await next_message(other) for _ in range(count)]
    assert [m.payload.decode() for m in seen] == [payload for _, payload, _ in burst]


@pytest.mark.asyncio
async def test_retained_returns_the_retained_set_then_unsubscribes(mosquitto: Broker) -> None:
    async with watcher(mosquitto.url) as other:
        for topic in ("ha/device/a/config", "ha/device/b/config", "ha/sensor/c/config"):
            await other.publish(topic, topic.upper(), retain=True)
        async with MqttClient(cfg(mosquitto.url), will_topic=STATE) as client:
            await client.subscribe("t/live")
            found = await client.retained("ha/device/+/config", settle=0.2)
            assert found == {
                "ha/device/a/config": b"HA/DEVICE/A/CONFIG",
                "ha/device/b/config": b"HA/DEVICE/B/CONFIG",
            }
            await other.publish("ha/device/d/config", "late")  # no longer subscribed
            await other.publish("t/live", "live")
            assert (await next_message(client)).topic == "t/live"


@pytest.mark.asyncio
async def test_nothing_listening_is_a_connect_error(mosquitto: Broker) -> None:
    mosquitto.stop()
    with pytest.raises(MqttConnectError, match="cannot connect"):
        async with MqttClient(cfg(mosquitto.url), will_topic=STATE):
            pass


# -- user name and password -------------------------------------------------------------


@pytest.mark.asyncio
async def test_password_from_a_file_is_accepted(mosquitto_auth: Broker, tmp_path: Path) -> None:
    secret = tmp_path / "mqtt-password"
    secret.write_text(BROKER_PASSWORD + "\n")
    config = cfg(mosquitto_auth.url, username=BROKER_USER, password_file=secret)
    async with MqttClient(config, will_topic=STATE) as client:
        assert await client.retained(STATE, settle=0.1) == {STATE: b"online"}


@pytest.mark.asyncio
@pytest.mark.parametrize("version", ["5", "3.1.1"])
async def test_bad_password_is_refused(mosquitto_auth: Broker, version: str) -> None:
    config = cfg(mosquitto_auth.url, username=BROKER_USER, password="wrong", version=version)
    with pytest.raises(MqttConnectError, match="refused") as refused:
        async with MqttClient(config, will_topic=STATE):
            pass
    # mosquitto 2.0 answers "not authorised" (0x87; 3.1.1 code 5), others 0x86 (code 4)
    assert refused.value.code in (0x86, 0x87)


class RecordingBackoff(ReconnectBackoff):
    """The real backoff, remembering how each failure was classified."""

    def __init__(self) -> None:
        super().__init__(initial=0.05)
        self.kinds: list[bool] = []

    def failed(self, now: float, *, refused: bool = False) -> float:
        self.kinds.append(refused)
        return super().failed(now, refused=refused)


@pytest.mark.asyncio
async def test_a_refused_login_backs_off_and_a_closed_port_retries_fast(
    mosquitto_auth: Broker,
) -> None:
    async def session(_: MqttClient) -> None:
        raise AssertionError("never connected")

    wrong = cfg(mosquitto_auth.url, username=BROKER_USER, password="wrong")
    closed = cfg(f"mqtt://127.0.0.1:{free_port()}")
    for config, refused in ((wrong, True), (closed, False)):
        backoff = RecordingBackoff()
        loop = asyncio.ensure_future(run_with_reconnect(config, STATE, session, backoff=backoff))
        await eventually(lambda b=backoff: len(b.kinds) >= 2, timeout=10)
        loop.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await loop
        assert set(backoff.kinds) == {refused}


@pytest.mark.asyncio
@pytest.mark.parametrize(("connack", "refused"), [(3, False), (5, True)])
async def test_a_broker_that_is_unavailable_is_no_refused_login(
    connack: int, refused: bool
) -> None:
    """CONNACK 3 (server unavailable) passes: the normal backoff; 5 (not authorised) is a
    refused login: the long one."""

    async def session(_: MqttClient) -> None:
        raise AssertionError("never connected")

    backoff = RecordingBackoff()
    async with StubBroker(connack=connack) as url:
        config = cfg(url, version="3.1.1")
        loop = asyncio.ensure_future(run_with_reconnect(config, STATE, session, backoff=backoff))
        await eventually(lambda: len(backoff.kinds) >= 2, timeout=10)
        loop.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await loop
    assert set(backoff.kinds) == {refused}


# -- TLS --------------------------------------------------------------------------------


@pytest.mark.asyncio
async def test_tls_with_the_signing_ca(mosquitto_tls: Broker, tls_files: TlsFiles) -> None:
    config = cfg(mosquitto_tls.url, tls=TlsConfig(ca=tls_files.ca))
    async with MqttClient(config, will_topic=STATE) as client:
        assert await client.retained(STATE, settle=0.1) == {STATE: b"online"}


@pytest.mark.asyncio
async def test_tls_untrusted_ca_fails_unless_insecure(
    mosquitto_tls: Broker, tls_files: TlsFiles
) -> None:
    untrusted = cfg(mosquitto_tls.url, tls=TlsConfig(ca=tls_files.other_ca))
    with pytest.raises(MqttConnectError, match="CERTIFICATE_VERIFY_FAILED"):
        async with MqttClient(untrusted, will_topic=STATE):
            pass
    insecure = cfg(mosquitto_tls.url, tls=TlsConfig(ca=tls_files.other_ca, insecure=True))
    async with MqttClient(insecure, will_topic=STATE) as client:
        assert client.protocol == "5"


@pytest.mark.asyncio
async def test_tls_client_certificate(mosquitto_mtls: Broker, tls_files: TlsFiles) -> None:
    tls = TlsConfig(ca=tls_files.ca, cert=tls_files.client_cert, key=tls_files.client_key)
    async with MqttClient(cfg(mosquitto_mtls.url, tls=tls), will_topic=STATE) as client:
        assert await client.retained(STATE, settle=0.1) == {STATE: b"online"}
        assert nodelay(client)


# -- the reconnect loop -----------------------------------------------------------------


@pytest.mark.asyncio
async def test_run_with_reconnect_survives_a_broker_restart(mosquitto: Broker) -> None:
    sessions: asyncio.Queue[int] = asyncio.Queue()
    entered = 0
    received: asyncio.Queue[Message] = asyncio.Queue()
    states: list[str] = []

    async def session(client: MqttClient) -> None:
        nonlocal entered
        entered += 1
        await client.subscribe("t/in/#")
        sessions.put_nowait(entered)
        async for message in client.messages():
            received.put_nowait(message)

    loop = run_with_reconnect(
        cfg(mosquitto.url), STATE, session, backoff=ReconnectBackoff(initial=0.05, fast_max=0.2),
        on_state=states.append,
    )  # fmt: skip
    task = asyncio.ensure_future(loop)
    try:
        assert await within(sessions.get()) == 1
        await asyncio.to_thread(mosquitto.restart)
        assert await within(sessions.get()) == 2
        async with watcher(mosquitto.url) as other:
            await other.publish("t/in/after", "restart")
            assert await other.retained(STATE, settle=0.1) == {STATE: b"online"}
        message = await within(received.get())
        assert (message.topic, message.payload) == ("t/in/after", b"restart")
        assert states == ["online", "offline", "online"]
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    async with watcher(mosquitto.url) as other:  # cancelled = a clean exit
        assert await other.retained(STATE, settle=0.1) == {STATE: b"offline"}


@pytest.mark.asyncio
async def test_run_with_reconnect_returns_when_the_session_does(mosquitto: Broker) -> None:
    calls: list[MqttClient] = []

    async def session(client: MqttClient) -> None:
        calls.append(client)

    await within(run_with_reconnect(cfg(mosquitto.url), STATE, session))
    assert len(calls) == 1


# -- what mosquitto won't do: refuse MQTT 5, redeliver with DUP -------------------------


class StubBroker:
    """Speaks just enough MQTT 3.1.1 at byte level; refuses MQTT 5 like a 3.1.1 broker.

    On each SUBSCRIBE it answers SUBACK and then sends a QoS 1 PUBLISH with DUP set.
    """

    def __init__(
        self,
        *,
        silent: bool = False,
        mqtt5: str = "refuse",
        dies_on: bytes | None = None,
        connack: int = 0,
    ) -> None:
        self.silent = silent  # never answer CONNECT
        self.connack = connack  # the return code to a 3.1.1 CONNECT (3: server unavailable)
        # an MQTT 5 CONNECT: "refuse" it, "ignore" it (amqtt), "close", or "answer" it
        self.mqtt5 = mqtt5
        self.dies_on = dies_on  # a PUBLISH to this topic is never acknowledged: the link dies
        self.levels: list[int] = []
        self.server: asyncio.Server | None = None

    async def __aenter__(self) -> str:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        port = self.server.sockets[0].getsockname()[1]
        return f"mqtt://127.0.0.1:{port}"

    async def __aexit__(self, *exc: object) -> None:
        assert self.server is not None
        self.server.close()
        await self.server.wait_closed()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            await self._talk(reader, writer)
        except asyncio.IncompleteReadError:
            pass
        finally:
            writer.close()
            with contextlib.suppress(ConnectionError):
                await writer.wait_closed()

    async def _talk(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while True:
            first, body = await read_packet(reader)
            kind = first & 0xF0
            if kind == 0x10:  # CONNECT: protocol name (2 + 4 bytes), then the level
                self.levels.append(body[6])
                if self.silent or (body[6] == 5 and self.mqtt5 == "ignore"):
                    continue
                if body[6] == 5 and self.mqtt5 == "close":
                    return
                if body[6] == 5 and self.mqtt5 == "answer":
                    writer.write(b"\x20\x03\x00\x00\x00")  # CONNACK: success, no properties
                    await writer.drain()
                    continue
                if body[6] != 4:
                    writer.write(b"\x20\x02\x00\x01")  # unacceptable protocol version
                    await writer.drain()
                    return
                writer.write(bytes([0x20, 2, 0, self.connack]))
                if self.connack:
                    await writer.drain()
                    return
            elif kind == 0x30 and first & 0x06:  # PUBLISH QoS>0: PUBACK its id
                topic_length = int.from_bytes(body[0:2])
                if body[2 : 2 + topic_length] == self.dies_on:
                    await asyncio.sleep(0.2)
                    return  # the broker died before acknowledging
                writer.write(b"\x40\x02" + body[2 + topic_length : 4 + topic_length])
            elif kind == 0x80:  # SUBSCRIBE: SUBACK QoS 1, then a redelivered PUBLISH
                writer.write(b"\x90\x03" + body[0:2] + b"\x01")
                publish = b"\x00\x05cmd/x" + (7).to_bytes(2) + b"ON"
                writer.write(bytes([0x3A, len(publish)]) + publish)  # PUBLISH, DUP, QoS 1
            elif kind == 0xC0:
                writer.write(b"\xd0\x00")  # PINGRESP
            elif kind == 0xE0:
                return  # DISCONNECT
            await writer.drain()


async def read_packet(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    """(first byte: type and flags, the rest after the remaining length)."""
    first = (await reader.readexactly(1))[0]
    length, shift = 0, 0
    while True:
        byte = (await reader.readexactly(1))[0]
        length |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            break
    return first, await reader.readexactly(length)


@pytest.mark.asyncio
async def test_falls_back_to_3_1_1_when_the_broker_refuses_5() -> None:
    stub = StubBroker()
    async with stub as url, MqttClient(cfg(url, version="5"), will_topic=STATE) as client:
        assert client.protocol == "3.1.1"
    assert stub.levels == [5, 4]


@pytest.mark.asyncio
@pytest.mark.parametrize("mqtt5", ["ignore", "close"])
async def test_falls_back_to_3_1_1_when_the_broker_never_answers_5(
    mqtt5: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """amqtt takes an MQTT 5 CONNECT and never answers it (the CONNACK wait times out);
    RabbitMQ 3.x closes the connection (no wait at all: the CONNACK timeout is made
    endless here). Either way, no CONNACK on a connection that was made: try 3.1.1."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 0.5 if mqtt5 == "ignore" else 3600)
    stub = StubBroker(mqtt5=mqtt5)
    async with stub as url:
        client = MqttClient(cfg(url, version="5"), will_topic=STATE)
        await asyncio.wait_for(client.__aenter__(), timeout=30)
        assert client.protocol == "3.1.1"
        await client.__aexit__(None, None, None)
    assert stub.levels == [5, 4]


@pytest.mark.asyncio
async def test_no_fallback_when_nothing_listens(monkeypatch: pytest.MonkeyPatch) -> None:
    """Nothing accepted the connection: that is not a protocol question (one attempt)."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 0.5)
    stub = StubBroker()
    url = await stub.__aenter__()
    await stub.__aexit__()
    with pytest.raises(MqttConnectError) as refused:
        await MqttClient(cfg(url, version="5"), will_topic=STATE).__aenter__()
    assert not isinstance(refused.value, MqttUnansweredError)


@pytest.mark.asyncio
async def test_reconnects_ask_for_3_1_1_once_the_broker_refused_5(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(connection_module, "TIMEOUT", 0.5)
    stub = StubBroker(mqtt5="refuse")
    sessions: list[str] = []

    async def session(client: MqttClient) -> None:
        sessions.append(client.protocol)
        if len(sessions) == 1:
            raise MqttDisconnectedError("lost")

    async with stub as url:
        config = cfg(url, version="5")
        await asyncio.wait_for(
            run_with_reconnect(config, STATE, session, backoff=ReconnectBackoff(initial=0.01)),
            timeout=10,
        )
    assert sessions == ["3.1.1", "3.1.1"]
    assert stub.levels == [5, 4, 4]  # the second connect did not try 5 again


@pytest.mark.asyncio
async def test_a_broker_silent_to_5_is_asked_for_5_again_at_each_reconnect(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Silence is not a refusal: the broker may have been stalled at that moment, and on
    3.1.1 a live retained command loses its retain flag. Said once a run (WARNING)."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 0.5)
    stub = StubBroker(mqtt5="ignore")
    sessions: list[str] = []

    async def session(client: MqttClient) -> None:
        sessions.append(client.protocol)
        if len(sessions) == 1:
            raise MqttDisconnectedError("lost")

    async with stub as url:
        config = cfg(url, version="5")
        await asyncio.wait_for(
            run_with_reconnect(config, STATE, session, backoff=ReconnectBackoff(initial=0.01)),
            timeout=10,
        )
    assert sessions == ["3.1.1", "3.1.1"]
    assert stub.levels == [5, 4, 5, 4]
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len([m for m in said if "left an MQTT 5 CONNECT unanswered" in m]) == 1


@pytest.mark.asyncio
async def test_a_broker_stalled_at_the_first_connect_gets_mqtt_5_once_it_answers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Found by the soak (issue 38): a broker stalled when the bridge started (SIGSTOP,
    overload) leaves the MQTT 5 CONNECT unanswered, wakes up in time for the 3.1.1 one,
    and the bridge would have stayed on 3.1.1 for the whole run. A probe on a connection
    of its own (no will, its own client id) finds MQTT 5 answered; the 3.1.1 session
    ends and the next one is MQTT 5."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 0.5)
    monkeypatch.setattr(reconnect_module, "PROBE_FIRST", 0.2)
    stub = StubBroker(mqtt5="ignore")
    sessions: list[str] = []

    async def session(client: MqttClient) -> None:
        sessions.append(client.protocol)
        if len(sessions) == 1:
            stub.mqtt5 = "answer"  # the broker runs again
            await asyncio.sleep(3600)  # served until the probe's answer ends it

    async with stub as url:
        config = cfg(url, version="5")
        await asyncio.wait_for(
            run_with_reconnect(config, STATE, session, backoff=ReconnectBackoff(initial=0.01)),
            timeout=10,
        )
    assert sessions == ["3.1.1", "5"]
    assert stub.levels == [5, 4, 5, 5]  # the probe's CONNECT, then the session's


@pytest.mark.asyncio
async def test_the_mqtt_5_probe_on_a_real_broker_leaves_the_session_and_its_topics_alone(
    mosquitto: Broker,
) -> None:
    """The probe against mosquitto (the stub above stands for brokers mosquitto cannot
    play): it is answered, and it neither takes the session's connection over (its own
    client id) nor leaves a will or any message behind (no will, a clean DISCONNECT)."""
    seen: list[Message] = []
    async with (
        MqttClient(cfg(mosquitto.url, version="3.1.1"), will_topic=STATE) as client,
        MqttClient(cfg(mosquitto.url), will_topic="observer/state") as observer,
    ):
        await observer.subscribe("#")

        async def collect() -> None:
            async for message in observer.messages():
                seen.append(message)

        task = asyncio.create_task(collect())
        await eventually(lambda: any(m.topic == STATE for m in seen), 5)  # online, retained
        assert await within(client.answers_5(), 15)
        await client.publish("t/after-the-probe", "still here", qos=1)  # the session lives
        await eventually(lambda: any(m.topic == "t/after-the-probe" for m in seen), 5)
        task.cancel()
    topics = [m.topic for m in seen]
    assert set(topics) <= {STATE, "t/after-the-probe", "observer/state"}, topics
    assert [m.payload for m in seen if m.topic == STATE] == [b"online"]


@pytest.mark.asyncio
async def test_a_probe_unanswered_leaves_the_3_1_1_session_alone_and_tries_later(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An old broker (amqtt) never answers the probe: the session goes on, undisturbed,
    and the probes come further and further apart."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 0.2)
    monkeypatch.setattr(reconnect_module, "PROBE_FIRST", 0.1)
    stub = StubBroker(mqtt5="ignore")
    sessions: list[str] = []

    async def session(client: MqttClient) -> None:
        sessions.append(client.protocol)
        await eventually(lambda: stub.levels.count(5) >= 3, 10)  # two probes went out
        await client.publish("t/still", "here", qos=1)  # the session still works

    async with stub as url:
        await asyncio.wait_for(run_with_reconnect(cfg(url, version="5"), STATE, session), 15)
    assert sessions == ["3.1.1"]
    assert stub.levels.count(4) == 1  # one session throughout


@pytest.mark.asyncio
async def test_a_broker_that_answered_5_is_not_taken_for_an_old_one_when_it_stalls(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Found by the soak (bench/soak_faults.py, issue 38): a broker stopped for a while
    (SIGSTOP) let an MQTT 5 CONNECT go unanswered; the bridge took it for a broker without
    MQTT 5, reconnected with 3.1.1 and kept 3.1.1 for the rest of the run, where a live
    retained command arrives without its retain flag, and ran it. A broker this run knows
    answers MQTT 5 (the reconnect loop passes ``version="5"``) gets 5 again."""
    monkeypatch.setattr(connection_module, "TIMEOUT", 0.5)
    stub = StubBroker(mqtt5="ignore")  # stands for the stalled broker: no CONNACK to 5
    async with stub as url:
        with pytest.raises(MqttUnansweredError):
            await MqttClient(cfg(url, version="5"), will_topic=STATE, version="5").__aenter__()
    assert stub.levels == [5]  # no 3.1.1 try


@pytest.mark.asyncio
async def test_a_publish_waiting_for_its_ack_ends_when_the_broker_dies() -> None:
    """aiomqtt alone waits its whole 10 s timeout for a PUBACK that cannot come any more."""
    async with (
        StubBroker(dies_on=b"t/lost") as url,
        MqttClient(cfg(url, version="3.1.1"), will_topic=STATE) as client,
    ):
        async with asyncio.timeout(5):
            with pytest.raises(MqttDisconnectedError, match="connection lost"):
                await client.publish("t/lost", "x", qos=1)


@pytest.mark.asyncio
async def test_a_burst_cut_by_a_lost_connection_leaves_the_caller_free_to_reconnect() -> None:
    """On Python 3.11 a TaskGroup whose task fails while it waits leaves the waiting task
    marked as cancelling: the next await of the reconnect loop would end the MQTT side."""
    burst = [("t/a", "1", True), ("t/lost", "2", True), ("t/b", "3", True)]
    async with (
        StubBroker(dies_on=b"t/lost") as url,
        MqttClient(cfg(url, version="3.1.1"), will_topic=STATE) as client,
    ):
        async with asyncio.timeout(5):
            with pytest.raises(MqttDisconnectedError):
                await client.publish_many(burst)
    task = asyncio.current_task()
    assert task is not None and task.cancelling() == 0
    await asyncio.sleep(0)  # would raise CancelledError if a cancel were left pending


@pytest.mark.asyncio
async def test_dup_flag_and_mid_of_a_redelivery() -> None:
    async with (
        StubBroker() as url,
        MqttClient(cfg(url, version="3.1.1"), will_topic=STATE) as client,
    ):
        await client.subscribe("cmd/#")
        message = await next_message(client)
    assert message == Message(
        topic="cmd/x", payload=b"ON", qos=1, retain=False, duplicate=True, mid=7
    )


@pytest.mark.asyncio
async def test_cancelled_while_waiting_for_connack_leaves_nothing_running() -> None:
    stub = StubBroker(silent=True)
    async with stub as url:
        connecting = asyncio.ensure_future(MqttClient(cfg(url), will_topic=STATE).__aenter__())
        for _ in range(500):
            if stub.levels:
                break
            await asyncio.sleep(0.01)
        connecting.cancel()
        with pytest.raises(asyncio.CancelledError):
            await connecting
    await asyncio.sleep(0)
    leftovers = [task for task in asyncio.all_tasks() if "_misc_loop" in repr(task.get_coro())]
    assert leftovers == []
