"""The web page's rules without sockets: who gets in, which requests may change anything,
the ``bridge.web`` settings, the live feed and the bus window."""

from __future__ import annotations

from http import HTTPStatus
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from bridge.config import WebConfig, load_config_data
from bridge.core.entity import Entity
from bridge.core.health_report import BusSnapshot, Snapshot
from bridge.core.mapping import Point
from bridge.core.state import alarm_active
from bridge.errors import ConfigError
from bridge.web import page_url
from bridge.web.access import Access, change_refusal
from bridge.web.http import Request
from bridge.web.live import MAX_PENDING, WebFeed
from bridge.web.views import BusWindow

TOKEN = "0123456789abcdef"


def request(peer: str = "127.0.0.1", **headers: str) -> Request:
    names = {key.replace("_", "-").lower(): value for key, value in headers.items()}
    return Request("GET", "/api/overview", {}, names, peer=peer)


# --- access -----------------------------------------------------------------------------


def test_without_a_token_only_loopback_host_names_get_in() -> None:
    access = Access(token=None, proxies=frozenset())
    for host in ("127.0.0.1:8099", "localhost:8099", "LOCALHOST", "[::1]:8099", "127.0.0.1"):
        assert access.refusal(request(host=host)) is None, host
    for host in ("evil.example", "evil.example:8099", "127.0.0.1.evil.example", "", "[::2]"):
        refusal = access.refusal(request(host=host))
        assert refusal is not None and refusal.status == HTTPStatus.FORBIDDEN, host


def test_with_a_token_a_bearer_header_or_the_session_cookie_gets_in() -> None:
    access = Access(token=TOKEN, proxies=frozenset())
    assert access.refusal(request(authorization=f"Bearer {TOKEN}")) is None
    assert access.refusal(request(authorization=f"bearer {TOKEN}")) is None
    assert access.refusal(request(cookie=f"other=1; bridge_web={access.session()}")) is None
    for refused in (
        request(),
        request(authorization=f"Bearer {TOKEN}x"),
        request(authorization=f"Basic {TOKEN}"),
        request(cookie=f"bridge_web={TOKEN}"),  # the token itself is not the session
        request(cookie='bridge_web="unterminated'),
        request(host="evil.example"),
    ):
        refusal = access.refusal(refused)
        assert refusal is not None and refusal.status == HTTPStatus.UNAUTHORIZED, refused
    assert access.login(TOKEN) and not access.login(TOKEN[:-1]) and not access.login("")
    name, value = access.cookie_header("/")
    assert name == "Set-Cookie" and TOKEN not in value
    assert value == f"bridge_web={access.session()}; Path=/; HttpOnly; SameSite=Strict"
    assert Access(token=None, proxies=frozenset()).login("") is False


def test_a_token_of_spaces_is_no_token_and_a_wide_page_without_one_lets_nobody_in() -> None:
    with pytest.raises(ValidationError, match="spaces do not count"):
        WebConfig(enabled=True, host="0.0.0.0", token=" " * 16)
    with pytest.raises(ValidationError, match="spaces do not count"):
        WebConfig(enabled=True, host="0.0.0.0", token=" " * 15 + "a")
    wide = Access(token=None, proxies=frozenset(), loopback=False)
    for host in ("localhost", "127.0.0.1:8099"):  # a client names any Host it likes
        refusal = wide.refusal(request(peer="192.168.1.50", host=host))
        assert refusal is not None and refusal.status == HTTPStatus.FORBIDDEN


def test_a_token_file_that_holds_no_token_keeps_the_page_shut(tmp_path: Path) -> None:
    blank = tmp_path / "token"
    blank.write_text("   \n")
    web = WebConfig(enabled=True, host="0.0.0.0", token_file=blank)
    with pytest.raises(ConfigError, match="token is missing"):
        Access.of(web)


def test_the_ingress_proxy_needs_no_token_and_nobody_else_gets_in_without_one() -> None:
    access = Access(token=None, proxies=frozenset({"172.30.32.2"}))
    assert access.refusal(request(peer="172.30.32.2", host="anything")) is None
    assert access.refusal(request(peer="::ffff:172.30.32.2")) is None  # IPv4-mapped
    refusal = access.refusal(request(peer="172.30.32.3", host="127.0.0.1"))
    assert refusal is not None and refusal.status == HTTPStatus.FORBIDDEN
    with_token = Access(token=TOKEN, proxies=frozenset({"172.30.32.2"}))
    assert with_token.refusal(request(peer="172.30.32.2")) is None
    assert with_token.refusal(request(peer="10.0.0.9", authorization=f"Bearer {TOKEN}")) is None


def post(peer: str = "127.0.0.1", **headers: str) -> Request:
    names = {key.replace("_", "-").lower(): value for key, value in headers.items()}
    return Request("POST", "/api/request/device/scan", {}, names, b"{}", peer)


@pytest.mark.parametrize(
    ("headers", "proxied", "status"),
    [
        ({"content_type": "application/json", "host": "h:1"}, False, None),
        ({"content_type": "Application/JSON; charset=utf-8", "host": "h:1"}, False, None),
        ({"content_type": "text/plain"}, False, HTTPStatus.UNSUPPORTED_MEDIA_TYPE),
        ({}, False, HTTPStatus.UNSUPPORTED_MEDIA_TYPE),
        ({"content_type": "application/json", "sec_fetch_site": "cross-site"}, False, 403),
        ({"content_type": "application/json", "sec_fetch_site": "same-site"}, False, 403),
        ({"content_type": "application/json", "sec_fetch_site": "same-origin"}, False, None),
        ({"content_type": "application/json", "origin": "http://h:1", "host": "h:1"}, False, None),
        ({"content_type": "application/json", "origin": "http://e:1", "host": "h:1"}, False, 403),
        ({"content_type": "application/json", "origin": "null", "host": "h:1"}, False, 403),
        # behind the ingress the browser's origin is Home Assistant's, not ours
        ({"content_type": "application/json", "origin": "http://ha:8123", "host": "h"}, True, None),
        ({"content_type": "application/json", "sec_fetch_site": "cross-site"}, True, 403),
    ],
)
def test_only_the_page_itself_may_change_anything(
    headers: dict[str, str], proxied: bool, status: int | None
) -> None:
    refusal = change_refusal(post(**headers), proxied=proxied)
    assert (refusal.status if refusal else None) == status


# --- bridge.web settings ----------------------------------------------------------------


def test_the_page_is_off_by_default_and_on_loopback_when_on() -> None:
    web = WebConfig()
    assert not web.enabled and web.host == "127.0.0.1" and web.port == 8099 and web.loopback
    assert WebConfig(enabled=True).token_value() is None
    for host in ("localhost", "127.0.0.5", "::1"):
        assert WebConfig(host=host).loopback, host
    for host in ("0.0.0.0", "192.168.1.10", "::", "bridge.local"):
        assert not WebConfig(host=host).loopback, host


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"enabled": True, "host": "0.0.0.0"}, "give a token"),
        ({"enabled": True, "host": "bridge.local"}, "give a token"),
        ({"token": "short"}, "at least 16 characters"),
        ({"token": TOKEN, "token_env": "X"}, "give one of token, token_file, token_env"),
        ({"ingress_proxies": ["not an address"]}, "ingress_proxies"),
    ],
)
def test_bad_web_settings_are_refused(settings: dict[str, Any], words: str) -> None:
    with pytest.raises(ValidationError, match=words):
        WebConfig(**settings)


def test_beyond_loopback_a_token_or_the_ingress_proxy_is_enough() -> None:
    assert WebConfig(enabled=True, host="0.0.0.0", token=TOKEN).token_value() == TOKEN
    ingress = WebConfig(enabled=True, host="0.0.0.0", ingress_proxies=["172.30.32.2"])
    assert [str(a) for a in ingress.ingress_proxies] == ["172.30.32.2"]


def config_with(web: dict[str, Any], folder: Path) -> Any:
    data = {
        "bridge": {"web": {"enabled": True, "host": "0.0.0.0"} | web},
        "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1"}],
    }
    return load_config_data(data, folder / "config.yaml")


def test_a_token_from_a_file_or_the_environment_is_checked_at_load(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "token").write_text(TOKEN + "\n")
    loaded = config_with({"token_file": str(tmp_path / "token")}, tmp_path)
    assert loaded.config.bridge.web.token_value() == TOKEN
    monkeypatch.setenv("WEB_TOKEN", TOKEN)
    assert config_with({"token_env": "WEB_TOKEN"}, tmp_path).config.bridge.web.token_value()

    (tmp_path / "weak").write_text("1234\n")
    cases = [
        ({"token_file": str(tmp_path / "missing")}, "bridge.web.token_file: cannot read"),
        ({"token_file": str(tmp_path / "weak")}, "shorter than 16 characters"),
        ({"token_env": "NO_SUCH_VARIABLE"}, "bridge.web.token_env: the token is missing"),
    ]
    for web, words in cases:
        with pytest.raises(ConfigError) as failed:
            config_with(web, tmp_path)
        assert any(words in issue for issue in failed.value.issues), failed.value.issues
    # a page that is off needs no token source to hold anything
    off = config_with({"enabled": False, "token_env": "NO_SUCH_VARIABLE"}, tmp_path)
    assert not off.config.bridge.web.enabled


def test_page_url_names_an_address_a_browser_can_open() -> None:
    assert page_url(WebConfig()) == "http://127.0.0.1:8099/"
    assert page_url(WebConfig(host="0.0.0.0", port=80, token=TOKEN)) == "http://127.0.0.1:80/"
    assert page_url(WebConfig(host="::1")) == "http://[::1]:8099/"
    assert page_url(WebConfig(host="10.1.2.3", token=TOKEN)) == "http://10.1.2.3:8099/"


# --- the feed and the bus window --------------------------------------------------------


def test_the_feed_merges_news_per_watcher_and_bounds_refusals() -> None:
    feed = WebFeed()
    feed.changed("pump", {"a"})  # nobody watches: nothing kept but nothing lost either
    with feed.watch("pump") as pump, feed.watch(None) as everything:
        assert feed.watchers == 2
        feed.changed("pump", {"a"})
        feed.changed("pump", frozenset({"b"}))
        feed.changed("starter", {"c"})
        assert pump.wake.is_set() and everything.wake.is_set()
        keys, refusals, changed = pump.take()
        assert (keys, refusals, changed) == ({"a", "b"}, [], True)
        assert not pump.wake.is_set() and pump.take() == (set(), [], False)
        assert everything.take()[0] == set()  # values only for the device it shows
        for n in range(MAX_PENDING + 5):
            feed.refused_command("pump", f'{{"key": "k{n}", "value": {n}, "error": "no"}}')
        _, refusals, _ = pump.take()
        assert len(refusals) == MAX_PENDING and refusals[-1]["value"] == MAX_PENDING + 4
        assert refusals[-1] | {"time": ""} == {
            "time": "",
            "device": "pump",
            "key": f"k{MAX_PENDING + 4}",
            "value": MAX_PENDING + 4,
            "error": "no",
        }
    assert feed.watchers == 0
    assert feed.refused == MAX_PENDING + 5 and len(feed.recent) == MAX_PENDING + 5


def snapshot(at: float, busy: float, requests: int) -> Snapshot:
    bus = BusSnapshot("tcp", "tcp", True, requests=requests, busy_seconds=busy)
    return Snapshot(wall=1e9 + at, monotonic=at, uptime=at, buses=(bus,))


def test_bus_utilisation_covers_the_last_seconds_only() -> None:
    window = BusWindow(window=10.0)
    first = window.report(snapshot(100.0, 50.0, 1000))["buses"]["tcp"]
    assert first["utilisation"] == 0.5  # since the start: 50 s busy of 100
    later = window.report(snapshot(104.0, 52.0, 1040))["buses"]["tcp"]
    assert later["utilisation"] == 0.5 and later["requests_per_s"] == 10.0
    window.report(snapshot(108.0, 52.0, 1040))
    # 20 s on: rates since the newest snapshot at least 10 s old (108): 6 busy seconds of 12
    last = window.report(snapshot(120.0, 58.0, 1100))["buses"]["tcp"]
    assert last["utilisation"] == 0.5 and last["requests_per_s"] == 5.0


# --- alarms, value by value -------------------------------------------------------------


def point(**fields: Any) -> Point:
    entity = Entity.model_validate({"name": "x", "address": 1} | fields)
    return Point(key="x", entity=entity, address=0, write_address=0, write_function=None)


def test_an_alarm_is_on_when_its_bit_is_on_or_its_code_is_not_normal() -> None:
    bit = point(table="discrete", alarm=True)
    assert alarm_active(bit, True) and not alarm_active(bit, False)
    assert not alarm_active(bit, None)
    code = point(alarm=True, enum={0: "none", 1: "overcurrent", 2: "standby"}, normal=[0, 2])
    assert alarm_active(code, "overcurrent")
    assert not alarm_active(code, "none") and not alarm_active(code, "standby")
    assert not alarm_active(code, None)
    assert not alarm_active(point(table="discrete"), True)  # not an alarm at all
