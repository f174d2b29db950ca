"""A small HTTP/1.1 server on the event loop: one request per connection, bounded everywhere.

Only what the web page and the metrics endpoint (bridge/metrics.py) need:
``GET``/``HEAD``/``POST`` with a ``Content-Length`` body, and Server-Sent Events. Every
connection is closed after its answer (``Connection: close``); an event stream stays open
until the client goes away or the server stops. Nothing a client sends can hold the
event loop or grow memory without bound:

- the request head is read within ``HEAD_TIMEOUT`` and is at most ``HEAD_LIMIT`` bytes
  (431 beyond), a body at most ``BODY_LIMIT`` bytes (413) read within ``HEAD_TIMEOUT``;
  chunked bodies are refused (411), so are other protocols than HTTP/1.x (505);
- at most ``MAX_CONNECTIONS`` connections at a time (503 beyond);
- an event stream whose client does not read is dropped after ``SEND_TIMEOUT``.

``handler(request)`` returns a ``Response`` or an ``EventStream``; whatever it raises is
logged and answered 500, never taken for the server's end.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from dataclasses import dataclass, field, replace
from http import HTTPStatus
from typing import Any
from urllib.parse import parse_qsl, unquote, urlsplit

log = logging.getLogger(__name__)
HEAD_LIMIT = 16 * 1024
BODY_LIMIT = 64 * 1024
BUSY_HEAD_TIMEOUT = 1.0  # seconds an over-the-cap connection may take to ask (answered 503)
HEAD_TIMEOUT = 10.0
SEND_TIMEOUT = 10.0
MAX_CONNECTIONS = 64
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
    """A request that cannot be answered normally; ``status`` says why."""

    def __init__(self, status: HTTPStatus, message: str) -> None:
        super().__init__(message)
        self.status = status


def parse_head(head: bytes, peer: str = "") -> tuple[Request, int]:
    """The request of a head (without body) and its Content-Length; BadRequestError."""
    request_line, *lines = head.decode("latin-1").rstrip("\r\n").split("\r\n")
    parts = request_line.split(" ")
    if len(parts) != 3 or not parts[0].isalpha() or not parts[1].startswith("/"):
        raise BadRequestError(HTTPStatus.BAD_REQUEST, "malformed request line")
    method, target, version = parts
    if version not in ("HTTP/1.1", "HTTP/1.0"):
        raise BadRequestError(HTTPStatus.HTTP_VERSION_NOT_SUPPORTED, "HTTP/1.x only")
    headers: dict[str, str] = {}
    for line in lines:
        name, colon, value = line.partition(":")
        if not colon or not name or name != name.strip():
            raise BadRequestError(HTTPStatus.BAD_REQUEST, "malformed header line")
        headers[name.lower()] = value.strip()
    if "transfer-encoding" in headers:
        raise BadRequestError(HTTPStatus.LENGTH_REQUIRED, "send a Content-Length body")
    length_text = headers.get("content-length", "0")
    if not length_text.isdigit() or len(length_text) > 9:
        raise BadRequestError(HTTPStatus.BAD_REQUEST, "bad Content-Length")
    length = int(length_text)
    if length > BODY_LIMIT:
        raise BadRequestError(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"at most {BODY_LIMIT} bytes")
    try:
        split = urlsplit(target)
        query = dict(parse_qsl(split.query, max_num_fields=20))
    except ValueError as exc:  # "//[" (a broken IPv6 host), more than 20 query fields
        raise BadRequestError(HTTPStatus.BAD_REQUEST, f"bad request target: {exc}") from None
    request = Request(method.upper(), unquote(split.path), query, headers, peer=peer)
    return request, length


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
            pass  # the client went away or never finished asking: nothing to answer
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
        peer = writer.get_extra_info("peername")
        try:
            async with asyncio.timeout(BUSY_HEAD_TIMEOUT if busy else HEAD_TIMEOUT):
                head = await reader.readuntil(b"\r\n\r\n")
                request, length = parse_head(head, peer[0] if peer else "")
                body = await reader.readexactly(length) if length else b""
        except asyncio.IncompleteReadError:
            return  # closed before the end of the request
        except asyncio.LimitOverrunError:
            await self._answer(writer, plain(HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE, "too big"))
            return
        except BadRequestError as exc:
            await self._answer(writer, plain(exc.status, str(exc)))
            return
        if busy:  # answered once read: closing on unread bytes would reset the connection
            await self._answer(writer, plain(HTTPStatus.SERVICE_UNAVAILABLE, "too busy"))
            return
        request = replace(request, body=body)
        try:
            answer = await self.handler(request)
        except Exception:  # a bug in one page must not end the server
            log.exception("web request %s %s failed", request.method, request.path[:200])
            answer = plain(HTTPStatus.INTERNAL_SERVER_ERROR, "internal error (see the log)")
        if isinstance(answer, EventStream):
            await self._stream(reader, writer, answer)
        else:
            await self._answer(writer, answer, head_only=request.method == "HEAD")

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
    http = HttpServer(handler)
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
