"""A small HTTP/1.1 server on the event loop: one request per connection, bounded everywhere.

Only what the web page and the metrics endpoint (bridge/metrics.py) need:
``GET``/``HEAD``/``POST`` with a ``Content-Length`` body, and Server-Sent Events. h11
parses requests (``RequestParser``: stricter than h11 where a proxy in front could frame a
request otherwise); answers are written here. Every connection is closed after its answer
(``Connection: close``); an event stream stays open until the client goes away or the
server stops. Nothing a client sends can hold the event loop, grow memory without bound,
or fill the log:

- the request is read within ``head_timeout`` (408 if it started and did not end), its
  head is at most ``HEAD_LIMIT`` bytes (431), its body at most ``BODY_LIMIT`` bytes (413);
  chunked bodies are refused (411), other protocols than HTTP/1.x (505), and whatever
  else ``RequestParser`` refuses (400, 501): one ``RefusalLog`` line a minute at most;
- at most ``MAX_CONNECTIONS`` connections at a time (503 beyond);
- an event stream whose client does not read is dropped after ``SEND_TIMEOUT``.

``handler(request)`` returns a ``Response`` or an ``EventStream``; whatever it raises is
logged and answered 500, never taken for the server's end.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import re
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from dataclasses import dataclass, field, replace
from http import HTTPStatus
from typing import Any
from urllib.parse import parse_qsl, unquote, urlsplit

import h11

log = logging.getLogger(__name__)
HEAD_LIMIT = 16 * 1024
BODY_LIMIT = 64 * 1024
BUSY_HEAD_TIMEOUT = 1.0  # seconds an over-the-cap connection may take to ask (answered 503)
HEAD_TIMEOUT = 10.0
SEND_TIMEOUT = 10.0
MAX_CONNECTIONS = 64
READ_SIZE = 4096  # bytes read from a connection at a time
REFUSAL_LOG_INTERVAL = 60.0  # seconds between two log lines about refused requests
# The methods of RFC 9110 and PATCH, case-sensitive: the handler answers 405 for those its
# pages do not serve, the server 501 for any other (``get`` is not ``GET``).
METHODS = frozenset(
    {"GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS", "TRACE", "CONNECT"}
)
SECURITY_HEADERS = (
    ("Cache-Control", "no-store"),
    ("X-Content-Type-Options", "nosniff"),
    ("Referrer-Policy", "no-referrer"),
    (
        "Content-Security-Policy",
        "default-src 'self'; img-src 'self' data:; frame-ancestors 'self'; form-action 'self'",
    ),
)


@dataclass(frozen=True, slots=True)
class Request:
    """One request: the path is percent-decoded, header names are lower case."""

    method: str
    path: str
    query: dict[str, str]
    headers: dict[str, str]
    body: bytes = b""
    peer: str = ""  # the client's address


@dataclass(frozen=True, slots=True)
class Response:
    status: int
    body: bytes = b""
    content_type: str = "text/plain; charset=utf-8"
    headers: tuple[tuple[str, str], ...] = ()


class EventSink:
    """Where an event stream writes: ``send`` one event, ``comment`` a keep-alive."""

    def __init__(self, writer: asyncio.StreamWriter) -> None:
        self._writer = writer

    async def send(self, event: str, data: str) -> None:
        lines = "".join(f"data: {line}\n" for line in data.split("\n"))
        await self._write(f"event: {event}\n{lines}\n")

    async def comment(self, text: str) -> None:
        await self._write(f": {text}\n\n")

    async def _write(self, text: str) -> None:
        self._writer.write(text.encode("utf-8"))
        try:
            async with asyncio.timeout(SEND_TIMEOUT):
                await self._writer.drain()
        except TimeoutError:
            raise ConnectionResetError("the client does not read its event stream") from None


@dataclass(frozen=True, slots=True)
class EventStream:
    """A Server-Sent Events answer: ``run(sink)`` writes events until it returns."""

    run: Callable[[EventSink], Coroutine[Any, Any, None]]
    headers: tuple[tuple[str, str], ...] = ()


Handler = Callable[[Request], Awaitable[Response | EventStream]]


class BadRequestError(Exception):
    """A request that cannot be answered normally; ``status`` says why, the message is one
    short printable line (client bytes escaped)."""

    def __init__(self, status: HTTPStatus, message: str) -> None:
        super().__init__(_printable(message))
        self.status = status


class RequestParser:
    """Bytes in, one ``Request`` out. Refused (BadRequestError): what h11 refuses (lines
    out of the grammar, control bytes, a bad Content-Length, two Hosts or none in HTTP/1.1,
    a head over ``HEAD_LIMIT``: 431); what it lets through but a proxy in front may frame
    otherwise (bare LF line ends, folded lines, Content-Length twice or with Transfer-
    Encoding); a target other than a path (``//host/...``, ``http://...``, ``*``); methods
    outside ``METHODS`` (501); versions other than 1.0 and 1.1 (505); a body over
    ``BODY_LIMIT`` (413) or chunked (411)."""

    def __init__(self, peer: str = "") -> None:
        self._h11 = h11.Connection(h11.SERVER, max_incomplete_event_size=HEAD_LIMIT)
        self.peer = peer
        self._head: bytearray | None = bytearray()  # the bytes of the head until it is parsed
        self._request: Request | None = None
        self._body = bytearray()
        self.started = False  # a byte came

    def feed(self, data: bytes) -> Request | None:
        """The request once complete, else None (feed more); ``b""`` = the client closed
        (ConnectionResetError unless complete). BadRequestError: see the class."""
        self.started = self.started or bool(data)
        if self._head is not None:
            self._head += data
        self._h11.receive_data(data)
        try:
            while (event := self._h11.next_event()) is not h11.NEED_DATA:
                if isinstance(event, h11.Request):
                    self._request = self._start(event)
                elif isinstance(event, h11.Data):
                    self._body += event.data
                elif isinstance(event, h11.EndOfMessage) and self._request is not None:
                    return replace(self._request, body=bytes(self._body))
                else:  # ConnectionClosed before a request
                    raise ConnectionResetError("closed before asking")
        except h11.RemoteProtocolError as exc:
            if not data:
                raise ConnectionResetError("closed before the end of the request") from None
            raise BadRequestError(HTTPStatus(exc.error_status_hint), str(exc)) from None
        return None

    def _start(self, event: h11.Request) -> Request:
        received, self._head = bytes(self._head or b""), None
        end = _HEAD_END.search(received)
        head = received[: end.end() if end else len(received)]
        _check_framing(head)
        if event.http_version not in (b"1.0", b"1.1"):
            raise BadRequestError(HTTPStatus.HTTP_VERSION_NOT_SUPPORTED, "HTTP/1.x only")
        method, target = event.method.decode("ascii"), event.target.decode("ascii")
        if method not in METHODS:
            raise BadRequestError(HTTPStatus.NOT_IMPLEMENTED, f"no method {method!r} here")
        if not target.startswith("/") or target.startswith("//"):
            raise BadRequestError(HTTPStatus.BAD_REQUEST, f"not a path: {target!r}")
        headers = {name.decode("ascii"): value.decode("latin-1") for name, value in event.headers}
        if "transfer-encoding" in headers:
            if "content-length" in headers:
                raise BadRequestError(
                    HTTPStatus.BAD_REQUEST, "Content-Length and Transfer-Encoding"
                )
            raise BadRequestError(HTTPStatus.LENGTH_REQUIRED, "send a Content-Length body")
        if int(headers.get("content-length", "0")) > BODY_LIMIT:
            raise BadRequestError(
                HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"at most {BODY_LIMIT} bytes"
            )
        split = urlsplit(target)  # a path: no host part, nothing urlsplit could refuse
        try:
            query = dict(parse_qsl(split.query, max_num_fields=20))
        except ValueError as exc:  # more than 20 query fields
            raise BadRequestError(HTTPStatus.BAD_REQUEST, f"bad query: {exc}") from None
        return Request(method, unquote(split.path), query, headers, peer=self.peer)


_HEAD_END = re.compile(rb"\n\r?\n")  # where h11 ends a head
_BARE_LF = re.compile(rb"(?<!\r)\n")
_FOLDED = re.compile(rb"\n[ \t]")
_CONTENT_LENGTH = re.compile(rb"^content-length:([^\r\n]*)", re.IGNORECASE | re.MULTILINE)


def _check_framing(head: bytes) -> None:
    """What h11 tolerates in a head and a proxy in front may frame otherwise."""
    if len(head) > HEAD_LIMIT:
        raise BadRequestError(HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE, "head too big")
    if _BARE_LF.search(head):
        raise BadRequestError(HTTPStatus.BAD_REQUEST, "a line ends in LF without CR")
    if _FOLDED.search(head):
        raise BadRequestError(HTTPStatus.BAD_REQUEST, "a folded header line")
    lengths = _CONTENT_LENGTH.findall(head)
    if len(lengths) > 1 or b"," in b"".join(lengths):
        raise BadRequestError(HTTPStatus.BAD_REQUEST, "more than one Content-Length")


def _printable(text: str, limit: int = 120) -> str:
    """One log line's worth of ``text``: control characters escaped, cut at ``limit``."""
    if not text.isprintable():
        text = text.encode("unicode_escape").decode("ascii")
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(slots=True)
class RefusalLog:
    """At most one warning per ``interval`` seconds about refused requests: the first one's
    peer, status and reason, and how many were left out since the last line. A client
    sending garbage in a loop costs a line a minute, not a line (or a traceback) a try."""

    what: str = "web page"
    interval: float = REFUSAL_LOG_INTERVAL
    clock: Callable[[], float] = time.monotonic
    _quiet_until: float = -math.inf
    _left_out: int = 0

    def note(self, peer: str, refusal: BadRequestError) -> None:
        now = self.clock()
        if now < self._quiet_until:
            self._left_out += 1
            return
        more = f" ({self._left_out} more refused since the last line)" if self._left_out else ""
        status, reason = int(refusal.status), str(refusal)
        log.warning("%s: refused a request from %s: %d %s%s", self.what, peer, status, reason, more)
        self._quiet_until, self._left_out = now + self.interval, 0


def encode_head(status: int, headers: tuple[tuple[str, str], ...]) -> bytes:
    phrase = HTTPStatus(status).phrase
    lines = [f"HTTP/1.1 {status} {phrase}", *(f"{k}: {v}" for k, v in headers)]
    return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")


def plain(status: HTTPStatus, message: str) -> Response:
    return Response(status, (message + "\n").encode("utf-8"))


@dataclass(slots=True)
class HttpServer:
    """Serves ``handler`` over connections accepted by ``asyncio.start_server``."""

    handler: Handler
    max_connections: int = MAX_CONNECTIONS
    head_timeout: float = HEAD_TIMEOUT  # seconds to send the request, head and body
    busy_head_timeout: float = BUSY_HEAD_TIMEOUT  # the same over the cap (answered 503)
    refusals: RefusalLog = field(default_factory=RefusalLog)
    _tasks: set[asyncio.Task[None]] = field(default_factory=set)
    _closing: bool = False

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """One connection: one request and its answer (or an event stream), then close."""
        task = asyncio.current_task()
        if task is not None:  # always: asyncio runs each connection's handler in a task
            self._tasks.add(task)
        try:
            open_now = len(self._tasks)
            if open_now > 2 * self.max_connections:
                return  # far beyond the cap: closed unread, nothing held
            await self._one_request(reader, writer, busy=open_now > self.max_connections)
        except (ConnectionError, TimeoutError):
            pass  # the client went away or does not read its answer
        except asyncio.CancelledError:
            if not self._closing:
                raise
            # ``close()`` ended this connection: end quietly (asyncio 3.11 logs a cancelled
            # connection task as an error)
        finally:
            if task is not None:
                self._tasks.discard(task)
            writer.close()

    async def _one_request(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, *, busy: bool
    ) -> None:
        request = await self._read(reader, writer, busy=busy)
        if request is None:
            return
        if busy:  # answered once read: closing on unread bytes would reset the connection
            await self._answer(writer, plain(HTTPStatus.SERVICE_UNAVAILABLE, "too busy"))
            return
        try:
            answer = await self.handler(request)
        except Exception:  # a bug in one page must not end the server
            log.exception("web request %s %s failed", request.method, request.path[:200])
            answer = plain(HTTPStatus.INTERNAL_SERVER_ERROR, "internal error (see the log)")
        if isinstance(answer, EventStream):
            await self._stream(reader, writer, answer)
        else:
            await self._answer(writer, answer, head_only=request.method == "HEAD")

    async def _read(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, *, busy: bool
    ) -> Request | None:
        """The request, or None when refused (answered, one log line at most) or when the
        client closed or stayed silent (nothing to answer). ConnectionError."""
        peer = writer.get_extra_info("peername")
        parser = RequestParser(peer[0] if peer else "")
        timeout = self.busy_head_timeout if busy else self.head_timeout
        try:
            async with asyncio.timeout(timeout):
                while (request := parser.feed(await reader.read(READ_SIZE))) is None:
                    pass
            return request
        except TimeoutError:
            if not parser.started:
                return None  # a connection opened and not used (browsers open spares)
            refusal = BadRequestError(HTTPStatus.REQUEST_TIMEOUT, f"not sent within {timeout:g} s")
        except BadRequestError as exc:
            refusal = exc
        self.refusals.note(parser.peer, refusal)
        await self._answer(writer, plain(refusal.status, str(refusal)))
        return None

    async def _answer(
        self, writer: asyncio.StreamWriter, response: Response, *, head_only: bool = False
    ) -> None:
        headers = (
            ("Content-Type", response.content_type),
            ("Content-Length", str(len(response.body))),
            ("Connection", "close"),
            *SECURITY_HEADERS,
            *response.headers,
        )
        writer.write(encode_head(response.status, headers))
        if not head_only:
            writer.write(response.body)
        async with asyncio.timeout(SEND_TIMEOUT):
            await writer.drain()

    async def _stream(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, stream: EventStream
    ) -> None:
        headers = (
            ("Content-Type", "text/event-stream; charset=utf-8"),
            ("Connection", "close"),
            ("X-Accel-Buffering", "no"),  # proxies (ingress) pass events on at once
            *SECURITY_HEADERS,
            *stream.headers,
        )
        writer.write(encode_head(200, headers))
        try:
            async with asyncio.TaskGroup() as group:
                streaming = group.create_task(stream.run(EventSink(writer)))
                watching = group.create_task(_until_closed(reader))
                streaming.add_done_callback(lambda _: watching.cancel())
                watching.add_done_callback(lambda _: streaming.cancel())
        except* (ConnectionError, TimeoutError):
            pass  # the client went away
        except* Exception:  # a bug in one stream must not end the server
            log.exception("web event stream failed")

    async def close(self) -> None:
        """End every connection (event streams included) and wait for them."""
        self._closing = True
        tasks = list(self._tasks)
        for task in tasks:
            task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.gather(*tasks, return_exceptions=True)


async def _until_closed(reader: asyncio.StreamReader) -> None:
    """Return when the client closes its side (whatever it sends meanwhile is ignored)."""
    while await reader.read(1024):
        pass


@contextlib.asynccontextmanager
async def listening(handler: Handler, host: str, port: int, what: str) -> AsyncIterator[None]:
    """Serve ``handler`` on ``host:port`` for the duration of the block, then stop listening
    and end open connections. OSError naming ``what`` and the address when it cannot."""
    http = HttpServer(handler, refusals=RefusalLog(what))
    try:
        server = await asyncio.start_server(http.serve, host, port, limit=HEAD_LIMIT)
    except OSError as exc:
        reason = str(exc.strerror or exc).rpartition(": ")[2]  # asyncio repeats the address
        raise OSError(exc.errno, f"{what}: cannot listen on {host}:{port}: {reason}") from None
    try:
        yield
    finally:
        server.close()
        await http.close()
        await server.wait_closed()
