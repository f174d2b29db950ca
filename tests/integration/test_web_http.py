"""The web page's HTTP server on real sockets: whatever a client sends or fails to read,
the server answers or drops it within bounds and keeps serving everyone else."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator

import pytest

from bridge.web import http as web_http
from bridge.web.http import EventSink, EventStream, HttpServer, Request, Response
from tests.integration.web import http, parse_answer
from tests.ports import free_port


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


GOOD = b"GET / HTTP/1.1\r\nHost: h\r\n\r\n"
H = b"Host: h\r\n"
# What a client may send instead of a request, and the status it gets: what a parser must
# refuse, what a proxy in front could frame otherwise (request smuggling), other protocols.
# The server's head timeout is TIMEOUT there (a client that waits to be spoken to gets 408).
TIMEOUT = 1.0
MALFORMED = [
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: \xb2\r\n\r\n", 400, id="length-superscript-2"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: 1\r\nContent-Length: 2\r\n\r\nab", 400, id="two-lengths-differing"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: 2\r\nContent-Length: 2\r\n\r\nab", 400, id="two-lengths-equal"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: 2, 2\r\n\r\nab", 400, id="length-list"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: -1\r\n\r\n", 400, id="length-negative"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: 99999999999\r\n\r\n", 413, id="length-huge"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: 70000\r\n\r\n", 413, id="body-too-big"),
    pytest.param(b"get / HTTP/1.1\r\n" + H + b"\r\n", 501, id="lowercase-method"),
    pytest.param(b"GET //evil.com/api/overview HTTP/1.1\r\n" + H + b"\r\n", 400, id="double-slash"),
    pytest.param(b"GET http://evil.com/api/overview HTTP/1.1\r\n" + H + b"\r\n", 400, id="absolute-form"),
    pytest.param(b"CONNECT evil.com:443 HTTP/1.1\r\n" + H + b"\r\n", 400, id="authority-form"),
    pytest.param(b"OPTIONS * HTTP/1.1\r\n" + H + b"\r\n", 400, id="asterisk-form"),
    pytest.param(b"GET noslash HTTP/1.1\r\n" + H + b"\r\n", 400, id="no-slash"),
    pytest.param(b"GET //[ HTTP/1.1\r\n" + H + b"\r\n", 400, id="broken-ipv6-host"),
    pytest.param(b"GET /?" + b"&".join(b"k%d=1" % i for i in range(30)) + b" HTTP/1.1\r\n" + H + b"\r\n", 400, id="30-query-fields"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Content-Length: 3\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n", 400, id="length-and-chunked"),
    pytest.param(b"POST / HTTP/1.1\r\n" + H + b"Transfer-Encoding: chunked\r\n\r\n0\r\n\r\n", 411, id="chunked"),
    pytest.param(b"GET / HTTP/1.1\r\n" + H + b"X-Folded: a\r\n b\r\n\r\n", 400, id="obs-fold"),
    pytest.param(b"GET / HTTP/1.1\n" + H + b"\r\n", 400, id="bare-lf-request-line"),
    pytest.param(b"GET / HTTP/1.1\nHost: h\n\n", 400, id="bare-lf-everywhere"),
    pytest.param(b"GET / HTTP/1.1\r\nHost : h\r\n\r\n", 400, id="space-before-colon"),
    pytest.param(b"GET / HTTP/1.1\r\n" + H + b"no colon here\r\n\r\n", 400, id="no-colon"),
    pytest.param(b"GET / HTTP/1.1\r\n\r\n", 400, id="no-host"),
    pytest.param(b"GET / HTTP/1.1\r\nHost: h\r\nHost: evil.example\r\n\r\n", 400, id="two-hosts"),
    pytest.param(b"GET / HTTP/1.1\r\n" + H + b"X-Big: " + b"a" * 20000 + b"\r\n\r\n", 431, id="head-too-big"),
    pytest.param(b"GET / HTTP/1.1\r\n" + H + b"X: y\r\n" * 3000 + b"\r\n", 431, id="too-many-headers"),
    pytest.param(b"GET /\x00 HTTP/1.1\r\n" + H + b"\r\n", 400, id="nul-in-target"),
    pytest.param(b"GET / HTTP/1.1\r\nHost: h\x00evil\r\n\r\n", 400, id="nul-in-header"),
    pytest.param(b"GET / HTTP/1.1\r\n" + H + b"X: \rCR\r\n\r\n", 400, id="bare-cr"),
    pytest.param(b"GET / HTTP/2.0\r\n" + H + b"\r\n", 505, id="http-2"),
    pytest.param(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n", 505, id="h2-preface"),
    pytest.param(b"GARBAGE\r\n\r\n", 400, id="garbage"),
    pytest.param(b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03" + bytes(range(256)), 400, id="tls-client-hello"),
    pytest.param(b"SSH-2.0-OpenSSH_9.6\r\n", 408, id="ssh"),  # waits for the server's banner
]  # fmt: skip


def refusal_lines(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    """The server's lines about refused requests; nothing at ERROR, no traceback, anywhere."""
    for record in caplog.records:
        assert record.levelno < logging.ERROR, record.getMessage()
        assert record.exc_info is None and record.stack_info is None, record.getMessage()
    return [r for r in caplog.records if "refused a request" in r.getMessage()]


@pytest.mark.asyncio
@pytest.mark.parametrize(("sent", "expected"), MALFORMED)
async def test_a_malformed_request_gets_a_status_and_one_log_line(
    sent: bytes, expected: int, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    async with serving(HttpServer(echo, head_timeout=TIMEOUT)) as port:
        assert status(await raw(port, sent)) == expected
        assert status(await raw(port, GOOD)) == 200  # still serving
    [line] = refusal_lines(caplog)
    assert line.levelno == logging.WARNING
    message = line.getMessage()
    assert message.startswith(f"web page: refused a request from 127.0.0.1: {expected} "), message
    assert "\n" not in message and "\x00" not in message and len(message) < 250, message


@pytest.mark.asyncio
async def test_a_burst_of_malformed_requests_is_one_log_line(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """About 50 GB of tracebacks a day from one client, before: now a line a minute."""
    caplog.set_level(logging.DEBUG)
    async with serving(HttpServer(echo, head_timeout=TIMEOUT)) as port:
        for _ in range(3):
            answers = await asyncio.gather(*(raw(port, p.values[0]) for p in MALFORMED))
            assert [status(a) for a in answers] == [p.values[1] for p in MALFORMED]
        assert status(await raw(port, GOOD)) == 200
    assert len(refusal_lines(caplog)) == 1


@pytest.mark.asyncio
async def test_a_head_dribbled_slower_than_the_timeout_is_answered_408(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Slow headers: the timeout is for the whole request, not for each byte."""
    caplog.set_level(logging.DEBUG)
    async with serving(HttpServer(echo, head_timeout=0.3)) as port:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)

        async def dribble() -> None:
            for byte in b"GET / HTTP/1.1\r\nHost: h\r\nX-Slow: " + b"a" * 1000:
                writer.write(bytes([byte]))
                await asyncio.sleep(0.02)

        sending = asyncio.create_task(dribble())
        try:
            async with asyncio.timeout(10):
                answer = await reader.read(-1)
        finally:
            sending.cancel()
            writer.close()
        assert status(answer) == 408
        assert not sending.done() or sending.cancelled()  # answered while still dribbling
        assert status(await raw(port, GOOD)) == 200
    [line] = refusal_lines(caplog)
    assert "408 not sent within 0.3 s" in line.getMessage()


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
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG)
    async with serving(HttpServer(echo, head_timeout=0.3)) as port:
        assert status(await raw(port, b"GET / HTTP/1.1\r\nHost: x\r\n")) == 408  # no blank line
        body_short = b"POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 10\r\n\r\nabc"
        assert status(await raw(port, body_short)) == 408
        assert await raw(port, body_short, close=True) == b""  # closed mid-body: gone
        assert await raw(port, b"GET / HT", close=True) == b""  # closed mid-head: gone
        assert await raw(port, b"") == b""  # opened, never used: closed without a word
    assert len(refusal_lines(caplog)) == 1  # the first 408; the second within the minute


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
        writer.write(b"GET /flood HTTP/1.1\r\nHost: h\r\n\r\n")
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
        writer.write(b"GET /flood HTTP/1.1\r\nHost: h\r\n\r\n")
        head = await reader.readuntil(b"\r\n\r\n")
        assert b"text/event-stream" in head
        writer.close()
        async with asyncio.timeout(10):
            while server._tasks:
                await asyncio.sleep(0.05)
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /flood HTTP/1.1\r\nHost: h\r\n\r\n")
        await reader.readuntil(b"\r\n\r\n")
    assert not server._tasks  # closing the server ended the stream
    writer.close()
