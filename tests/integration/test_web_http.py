"""The web page's HTTP server on real sockets: whatever a client sends or fails to read,
the server answers or drops it within bounds and keeps serving everyone else."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

import pytest

from bridge.web import http as web_http
from bridge.web.http import EventSink, EventStream, HttpServer, Request, Response
from tests.integration.web import free_port, http, parse_answer


async def echo(request: Request) -> Response | EventStream:
    if request.path == "/boom":
        raise RuntimeError("a bug in a page")
    if request.path == "/flood":

        async def flood(sink: EventSink) -> None:
            while True:
                await sink.send("chunk", "x" * 65536)

        return EventStream(flood)
    if request.path == "/wait":
        await asyncio.sleep(30)
    text = f"{request.method} {request.path} {sorted(request.query.items())} {request.body!r}"
    return Response(200, text.encode())


@contextlib.asynccontextmanager
async def serving(server: HttpServer) -> AsyncIterator[int]:
    port = free_port()
    listener = await asyncio.start_server(
        server.serve, "127.0.0.1", port, limit=web_http.HEAD_LIMIT
    )
    try:
        yield port
    finally:
        listener.close()
        await server.close()
        await listener.wait_closed()


async def raw(port: int, data: bytes, *, close: bool = False) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(data)
        if close:
            writer.write_eof()
        async with asyncio.timeout(10):
            return await reader.read(-1)
    finally:
        writer.close()


def status(answer: bytes) -> int:
    return parse_answer(answer).status if answer else 0


@pytest.mark.asyncio
async def test_requests_are_parsed_and_answered() -> None:
    async with serving(HttpServer(echo)) as port:
        answer = await http(port, "POST", "/a%20b?x=1&y=two", b'{"k": 1}')
        assert answer.status == 200
        assert answer.body == b"POST /a b [('x', '1'), ('y', 'two')] b'{\"k\": 1}'"
        assert answer.headers["connection"] == "close"
        assert answer.headers["x-content-type-options"] == "nosniff"
        assert answer.headers["cache-control"] == "no-store"


@pytest.mark.asyncio
@pytest.mark.parametrize(
    ("sent", "expected"),
    [
        (b"GARBAGE\r\n\r\n", 400),
        (b"GET noslash HTTP/1.1\r\n\r\n", 400),
        (b"GET //[ HTTP/1.1\r\n\r\n", 400),  # urlsplit: invalid IPv6 URL
        (b"GET /?" + b"&".join(b"k%d=1" % i for i in range(30)) + b" HTTP/1.1\r\n\r\n", 400),
        (b"GET / HTTP/2.0\r\n\r\n", 505),
        (b"GET / HTTP/1.1\r\nno colon here\r\n\r\n", 400),
        (b"POST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n", 411),
        (b"POST / HTTP/1.1\r\nContent-Length: -1\r\n\r\n", 400),
        (b"POST / HTTP/1.1\r\nContent-Length: 99999999999\r\n\r\n", 400),
        (b"POST / HTTP/1.1\r\nContent-Length: 70000\r\n\r\n", 413),
        (b"GET / HTTP/1.1\r\nX-Big: " + b"a" * 20000 + b"\r\n\r\n", 431),
    ],
)
async def test_bad_requests_get_a_status_and_nothing_else(sent: bytes, expected: int) -> None:
    async with serving(HttpServer(echo)) as port:
        assert status(await raw(port, sent)) == expected
        assert status(await raw(port, b"GET / HTTP/1.1\r\n\r\n")) == 200  # still serving


@pytest.mark.asyncio
async def test_a_handler_bug_is_a_500_and_the_server_carries_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with serving(HttpServer(echo)) as port:
        assert (await http(port, "GET", "/boom")).status == 500
        assert "web request GET /boom failed" in caplog.text
        assert (await http(port, "GET", "/")).status == 200


@pytest.mark.asyncio
async def test_a_client_that_never_finishes_its_request_is_dropped(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(web_http, "HEAD_TIMEOUT", 0.3)
    async with serving(HttpServer(echo)) as port:
        assert await raw(port, b"GET / HTTP/1.1\r\nHost: x\r\n") == b""  # no blank line
        body_short = b"POST / HTTP/1.1\r\nContent-Length: 10\r\n\r\nabc"
        assert await raw(port, body_short) == b""
        assert await raw(port, body_short, close=True) == b""  # closed mid-body


@pytest.mark.asyncio
async def test_connections_beyond_the_limit_are_answered_busy() -> None:
    server = HttpServer(echo, max_connections=2)
    async with serving(server) as port:
        waiting = [asyncio.create_task(http(port, "GET", "/wait")) for _ in range(2)]
        async with asyncio.timeout(5):
            while len(server._tasks) < 2:
                await asyncio.sleep(0.01)
        assert (await http(port, "GET", "/")).status == 503
        for task in waiting:
            task.cancel()
        await asyncio.gather(*waiting, return_exceptions=True)


@pytest.mark.asyncio
async def test_idle_sockets_beyond_the_limit_are_not_held() -> None:
    """Sockets that never ask: over the cap each is let go after BUSY_HEAD_TIMEOUT, far
    over it at once, so idle sockets cannot pile up (file descriptors the bridge needs)."""
    server = HttpServer(echo, max_connections=2)
    async with serving(server) as port:
        idle = [await asyncio.open_connection("127.0.0.1", port) for _ in range(20)]
        await asyncio.sleep(0.2)
        assert len(server._tasks) <= 2 * server.max_connections + 1
        async with asyncio.timeout(5):  # the over-the-cap ones go after 1 s
            while len(server._tasks) > server.max_connections:
                await asyncio.sleep(0.05)
        for _, writer in idle:
            writer.close()


@pytest.mark.asyncio
async def test_an_event_stream_nobody_reads_is_dropped(monkeypatch: pytest.MonkeyPatch) -> None:
    """A stuck browser tab cannot make the server buffer without end."""
    monkeypatch.setattr(web_http, "SEND_TIMEOUT", 0.5)
    server = HttpServer(echo)
    async with serving(server) as port:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /flood HTTP/1.1\r\n\r\n")
        await reader.readuntil(b"\r\n\r\n")  # the head, then never another read
        async with asyncio.timeout(20):
            while server._tasks:
                await asyncio.sleep(0.05)
        writer.close()


@pytest.mark.asyncio
async def test_an_event_stream_ends_when_its_client_goes_and_when_the_server_stops() -> None:
    server = HttpServer(echo)
    async with serving(server) as port:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /flood HTTP/1.1\r\n\r\n")
        head = await reader.readuntil(b"\r\n\r\n")
        assert b"text/event-stream" in head
        writer.close()
        async with asyncio.timeout(10):
            while server._tasks:
                await asyncio.sleep(0.05)
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /flood HTTP/1.1\r\n\r\n")
        await reader.readuntil(b"\r\n\r\n")
    assert not server._tasks  # closing the server ended the stream
    writer.close()
