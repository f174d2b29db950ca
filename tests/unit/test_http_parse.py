"""The web page's request parser (h11 and this server's stricter rules) and the log of
refused requests, without sockets. The table of malformed requests on a real socket, with
the status and the log line each gets, is in tests/integration/test_web_http.py."""

from __future__ import annotations

import logging
from http import HTTPStatus

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bridge.web.http import BODY_LIMIT, BadRequestError, RefusalLog, Request, RequestParser

POST = (
    b"POST /api/devices/a%2Fb?device=x&device=y HTTP/1.1\r\n"
    b"Host: h\r\nContent-Type:application/json\r\nContent-Length: 12\r\n\r\n"
    b'{"k": "v"}\r\n'
)
PARSED = Request(
    "POST",
    "/api/devices/a/b",
    {"device": "y"},
    {"host": "h", "content-type": "application/json", "content-length": "12"},
    b'{"k": "v"}\r\n',
    peer="10.0.0.1",
)


def parse(data: bytes) -> Request | None:
    return RequestParser("10.0.0.1").feed(data)


def refusal(data: bytes) -> BadRequestError:
    with pytest.raises(BadRequestError) as refused:
        parse(data)
    return refused.value


def test_a_request_is_parsed_whole() -> None:
    assert parse(POST) == PARSED


def test_a_request_may_come_a_byte_at_a_time() -> None:
    parser = RequestParser("10.0.0.1")
    *waiting, last = POST
    assert all(parser.feed(bytes([byte])) is None for byte in waiting)
    assert parser.feed(bytes([last])) == PARSED


def test_http_1_0_needs_no_host_and_head_is_a_request() -> None:
    head = Request("HEAD", "/metrics", {}, {}, peer="10.0.0.1")
    assert parse(b"HEAD /metrics HTTP/1.0\r\n\r\n") == head
    assert parse(b"GET /a#fragment HTTP/1.0\r\n\r\n") == Request(
        "GET", "/a", {}, {}, peer="10.0.0.1"
    )


@pytest.mark.parametrize(
    ("data", "status", "reason"),
    [
        (b"GET /?" + b"&".join(b"k%d=1" % i for i in range(50)) + b" HTTP/1.1\r\nHost: h\r\n\r\n",
         400, "bad query: Max number of fields exceeded"),
        (b"GET //[ HTTP/1.1\r\nHost: h\r\n\r\n", 400, "not a path: '//['"),
        (b"GET / HTTP/1.1\r\nHost: h\r\n Folded: header\r\n\r\n", 400, "a folded header line"),
        (b"GET / HTTP/1.1\r\nHost: h\r\nContent-Length: 1\r\nContent-length: 1\r\n\r\nx",
         400, "more than one Content-Length"),
        (b"GET / HTTP/1.1\r\nHost: h\r\nContent-Length: \xb2\r\n\r\n", 400, "bad Content-Length"),
        (b"POST / HTTP/1.1\r\nHost: h\r\nContent-Length: %d\r\n\r\n" % (BODY_LIMIT + 1),
         413, f"at most {BODY_LIMIT} bytes"),
        (b"POST / HTTP/1.1\r\nHost: h\r\nTransfer-Encoding: gzip\r\n\r\n", 501,
         "Only Transfer-Encoding: chunked is supported"),
        (b"Get / HTTP/1.1\r\nHost: h\r\n\r\n", 501, "no method 'Get' here"),
        (b"GET / HTTP/1.1\r\nHost: h\x00\x1b[2J\r\n\r\n", 400,
         "illegal header line: bytearray(b'Host: h\\x00\\x1b[2J')"),
    ],
)  # fmt: skip
def test_a_refusal_says_why_in_one_printable_line(data: bytes, status: int, reason: str) -> None:
    refused = refusal(data)
    assert (refused.status, str(refused)) == (status, reason)


def test_a_long_reason_is_cut() -> None:
    reason = str(refusal(b"GET / HTTP/1.1\r\nHost: h\r\nX : " + b"\x01" * 5000 + b"\r\n\r\n"))
    assert len(reason) == 120 and reason.endswith("...") and reason.isprintable()


def test_a_client_that_closes_early_is_gone_not_refused() -> None:
    for partial in (b"", b"GET / HT", b"POST / HTTP/1.1\r\nHost: h\r\nContent-Length: 5\r\n\r\nab"):
        parser = RequestParser()
        assert not partial or parser.feed(partial) is None
        with pytest.raises(ConnectionResetError):
            parser.feed(b"")
        assert parser.started == bool(partial)


@given(st.binary(max_size=300) | st.builds(lambda a, b: a + b, st.just(POST[:60]), st.binary()))
def test_whatever_a_client_sends_is_a_request_a_refusal_or_more_to_read(data: bytes) -> None:
    """No other exception (the old parser raised ValueError on ``Content-Length: ²``)."""
    parser = RequestParser()
    refused: BadRequestError | None = None
    try:
        for chunk in (data[:7], data[7:], b""):
            if chunk and parser.feed(chunk) is not None:
                return
        parser.feed(b"")
    except BadRequestError as exc:
        refused = exc
    except ConnectionResetError:
        return
    assert refused is not None  # a client that closed before the end is gone, else answered
    assert refused.status in (400, 411, 413, 431, 501, 505)
    assert str(refused).isprintable() and len(str(refused)) <= 120


# --- the log of refusals ----------------------------------------------------------------


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_refusals_are_one_line_a_minute_with_the_count_left_out(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    clock = Clock()
    refusals = RefusalLog("metrics endpoint", interval=60, clock=clock)
    bad = BadRequestError(HTTPStatus.BAD_REQUEST, "bad Content-Length")
    for _ in range(500):
        refusals.note("192.0.2.7", bad)
        clock.now += 0.001
    clock.now += 59
    refusals.note("192.0.2.8", BadRequestError(HTTPStatus.NOT_IMPLEMENTED, "no method 'get'"))
    clock.now += 1
    refusals.note("192.0.2.9", bad)
    assert [(r.levelname, r.getMessage()) for r in caplog.records] == [
        ("WARNING", "metrics endpoint: refused a request from 192.0.2.7: 400 bad Content-Length"),
        ("WARNING", "metrics endpoint: refused a request from 192.0.2.9: 400 bad Content-Length "
                    "(500 more refused since the last line)"),
    ]  # fmt: skip
