"""A relay between an MQTT client and a real broker that misbehaves on request: answers
late or never, or every connection cut at a chosen moment."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

from tests.integration.mosquitto import Broker

PUBACK = 0x40


class Relay:
    """Client <-> relay <-> broker. ``delay``: the broker's answers reach the client that
    many seconds late; ``hold``: they never do (a broker that stops acknowledging);
    ``hold_after``: the same after that many answers (2: the CONNACK and one SUBACK, so
    the session waits for the others);
    ``unanswered``: a topic filter whose first SUBSCRIBE the broker's SUBACK never answers
    (a cluster that did not create its consumer in time); ``late_pubacks``: the broker's
    PUBACKs reach the client that many seconds late, everything else at once (NATS storing
    each QoS 1 publish in JetStream while a stream elects its leader); ``cut()``: every connection closed at once (no await: the caller picks the moment) and
    new ones closed as soon as accepted, until ``mend()``."""

    def __init__(self, broker: Broker) -> None:
        self.broker = broker
        self.delay = 0.0
        self.hold = False
        self.hold_after: int | None = None
        self.unanswered: bytes | None = None
        self.late_pubacks = 0.0
        self._dropping: set[bytes] = set()  # packet ids of SUBSCRIBEs left unanswered
        self.url = ""
        self._open = True
        self._writers: set[asyncio.StreamWriter] = set()

    def cut(self) -> None:
        self._open = False
        for writer in list(self._writers):
            writer.transport.abort()

    def mend(self) -> None:
        self._open, self.hold, self.hold_after = True, False, None

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if not self._open:
            writer.transport.abort()
            return
        up_reader, up_writer = await asyncio.open_connection(self.broker.host, self.broker.port)
        self._writers |= {writer, up_writer}
        down = asyncio.ensure_future(self._down(up_reader, writer))
        pending = b""
        try:
            while chunk := await reader.read(65536):  # the client's packets: at once
                if self.unanswered is not None:
                    packets, pending = _split(pending + chunk)
                    for packet in packets:
                        wanted = self.unanswered
                        if packet[0] == 0x82 and wanted is not None and wanted in packet:
                            self._dropping.add(_packet_id(packet))
                            self.unanswered = None  # the first one only
                up_writer.write(chunk)
                await up_writer.drain()
        except ConnectionError:
            pass
        finally:
            self._writers -= {writer, up_writer}
            up_writer.close()  # no DISCONNECT passed: the broker sends the will
            writer.close()
            await asyncio.gather(down, return_exceptions=True)

    async def _down(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        loop = asyncio.get_running_loop()

        def write(chunk: bytes) -> None:
            if not writer.is_closing():
                writer.write(chunk)

        passed = 0
        pending = b""
        last = 0.0  # when the chunk before is due: none overtakes another when delay drops
        while chunk := await reader.read(65536):
            if self.hold:
                continue
            if self._dropping or pending or self.late_pubacks:  # whole packets only
                packets, pending = _split(pending + chunk)
                packets = [p for p in packets if not self._unanswered(p)]
                late = b"".join(p for p in packets if p[0] == PUBACK and self.late_pubacks)
                if late:
                    loop.call_later(self.late_pubacks, write, late)
                chunk = b"".join(p for p in packets if p[0] != PUBACK or not self.late_pubacks)
            if self.delay or last > loop.time():
                last = max(loop.time() + self.delay, last + 1e-6)
                loop.call_at(last, write, chunk)
            else:
                write(chunk)
            passed += 1
            self.hold |= passed == self.hold_after
        writer.close()

    def _unanswered(self, packet: bytes) -> bool:
        """A SUBACK of a SUBSCRIBE left unanswered (dropped once)."""
        if packet[0] != 0x90 or _packet_id(packet) not in self._dropping:
            return False
        self._dropping.discard(_packet_id(packet))
        return True


def _split(data: bytes) -> tuple[list[bytes], bytes]:
    """Whole MQTT packets at the start of ``data``, and the rest."""
    packets = []
    while len(data) >= 2:
        length, shift, at = 0, 0, 1
        while at < len(data) and at < 5:
            byte = data[at]
            length |= (byte & 0x7F) << shift
            shift, at = shift + 7, at + 1
            if not byte & 0x80:
                break
        else:
            break  # the length is not all there yet
        if len(data) < at + length:
            break
        packets.append(data[: at + length])
        data = data[at + length :]
    return packets, data


def _packet_id(packet: bytes) -> bytes:
    """The packet identifier right after the fixed header (SUBSCRIBE, SUBACK)."""
    at = 1
    while packet[at] & 0x80:
        at += 1
    return packet[at + 1 : at + 3]


@contextlib.asynccontextmanager
async def relayed(broker: Broker) -> AsyncIterator[tuple[Relay, str]]:
    relay = Relay(broker)
    server = await asyncio.start_server(relay.serve, "127.0.0.1", 0)
    relay.url = f"mqtt://127.0.0.1:{server.sockets[0].getsockname()[1]}"
    try:
        yield relay, relay.url
    finally:
        relay.cut()
        server.close()
