"""The web page's API end to end: a real bridge (real Mosquitto, the simulator behind) with
``bridge.web`` on, asked over plain sockets.

What the page shows must be what the bridge knows (the health snapshot, the pollers'
values, the ``<device>/error`` feed); commissioning must run through the management
code with its limits and guards; access and cross-site rules must hold for every route.
"""

from __future__ import annotations

import asyncio
import json
import logging
import subprocess
import sys
from pathlib import Path
from urllib.parse import urlsplit

import pytest

from bridge.app import Bridge
from bridge.cli.demo import SEEDS
from bridge.config import MqttConfig, load_config_data
from bridge.core.discovery_alarms import in_words
from bridge.core.entity import Table
from bridge.modbus.simulator import Quirks
from bridge.mqtt import MqttClient
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_demo import demo, read_until, stop
from tests.integration.web import PUMP, STARTER, TOKEN, events, http, site
from tests.ports import free_port

JSON = {"Content-Type": "application/json"}


def online(overview: dict, device_id: str) -> bool:
    return any(d["id"] == device_id and d["state"] == "online" for d in overview["devices"])


async def both_online(port: int) -> dict:
    """The overview once both devices answer."""
    async with asyncio.timeout(10):
        while True:
            overview = (await http(port, "GET", "/api/overview")).json()
            if online(overview, "pump") and online(overview, "starter"):
                return overview
            await asyncio.sleep(0.05)


@pytest.mark.asyncio
async def test_overview_and_device_pages_show_what_the_bridge_knows(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as s:
        overview = await both_online(s.port)
        assert overview["mqtt"] in ("online", "connecting")
        assert set(overview["subscriptions"]) == {"commands", "home_assistant", "bridge_info"}
        assert overview["raw_writes"] is False
        pump = next(d for d in overview["devices"] if d["id"] == "pump")
        assert pump | {"last_success": None} == pump | {
            "name": "Pump",
            "model": "Nastec VASCO / VASCO Solar / MIDA",
            "mapping": "nastec_vasco",
            "bus": "tcp",
            "unit": PUMP,
            "state": "online",
            "last_success": None,
        }
        assert pump["last_success"] and pump["requests"] > 0 and pump["errors"] == 0
        assert pump["latency_p50_ms"] is not None
        (bus,) = overview["buses"]
        assert bus["id"] == "tcp" and bus["connected"] is True and bus["transport"] == "tcp"
        assert 0 < bus["utilisation"] <= 1 and bus["requests"] > 0
        assert {"timeouts", "frame_errors", "exceptions", "requests_per_s"} <= set(bus)

        s.sim.set_value(PUMP, "motor_current", 7.5)
        await eventually(lambda: s.bridge.engine.devices["pump"].values.get("motor_current") == 7.5)
        device = (await http(s.port, "GET", "/api/devices/pump")).json()
        assert device["topic"] == "modbus/pump"
        rows = {row["key"]: row for row in device["values"]}
        decimals = rows["motor_current"]["decimals"]
        assert rows["motor_current"] == {
            "key": "motor_current",
            "name": "Motor current",
            "value": 7.5,
            "text": f"{7.5:.{decimals}f}",
            "unit": "A",
            "decimals": decimals,
            "alarm": False,
            "component": "sensor",
            "category": None,
            "writable": False,
        }
        assert "password_1_left" not in rows  # secrets are never shown
        assert device["status"] == s.bridge.engine.devices["pump"].values["status"]
        # the page speaks as Home Assistant does: labels in words, the key beside them
        assert device["status_text"] == in_words(device["status"])
        starter = (await http(s.port, "GET", "/api/devices/starter")).json()
        assert (starter["status"], starter["status_text"]) == ("no_fault", "No fault")
        fault = next(row for row in starter["values"] if row["key"] == "fault_status")
        assert (fault["value"], fault["text"]) == ("no_fault", "No fault")
        missing = await http(s.port, "GET", "/api/devices/nope")
        assert missing.status == 404


@pytest.mark.asyncio
async def test_events_carry_value_changes_alarms_and_a_device_going_offline_and_back(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as s:
        await both_online(s.port)
        async with events(s.port, "/api/events?device=pump") as stream:
            assert stream.status == 200
            first = await stream.next("overview")
            assert {d["id"] for d in first["devices"]} == {"pump", "starter"}
            device = await stream.next("device")
            assert device["id"] == "pump" and device["values"]
            assert await stream.next("errors") == []

            s.sim.set_value(PUMP, "motor_current", 12.5)
            change = await stream.next(
                "values", lambda d: d["values"].get("motor_current", {}).get("value") == 12.5
            )
            assert change["values"]["motor_current"]["unit"] == "A"

            s.sim.set_value(PUMP, "alarm_dry_running", True)
            alarm = await stream.next("values", lambda d: "alarm_dry_running" in d["values"])
            dry = alarm["values"]["alarm_dry_running"]
            assert (dry["alarm"], dry["value"], dry["text"]) == (True, True, "Problem")
            assert "alarm_dry_running" in alarm["alarms"]
            named = dict(zip(alarm["alarms"], alarm["alarm_names"], strict=True))
            assert named["alarm_dry_running"] == "Dry running"  # as Home Assistant names it
            assert alarm["status_text"] == in_words(alarm["status"])

            s.sim.set_quirks(PUMP, Quirks(dead=True))
            await stream.next("overview", lambda o: _state(o, "pump") == "offline")
            s.sim.set_quirks(PUMP, Quirks())
            back = await stream.next("overview", lambda o: _state(o, "pump") == "online", 20)
            assert _state(back, "starter") == "online"  # the other unit never left
        unknown = await http(s.port, "GET", "/api/events?device=nope")
        assert unknown.status == 404


def _state(overview: dict, device_id: str) -> str:
    return next(d["state"] for d in overview["devices"] if d["id"] == device_id)


@pytest.mark.asyncio
async def test_refused_commands_reach_the_page_live_and_in_the_list(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as s:
        await both_online(s.port)
        async with (
            events(s.port) as stream,
            MqttClient(MqttConfig(url=mosquitto.url), will_topic="t/state") as client,
        ):
            await stream.next("errors")
            await client.publish("modbus/pump/motor_current/set", "5")
            refused = await stream.next("refused")
            assert refused["device"] == "pump" and refused["key"] == "motor_current"
            assert refused["value"] == 5 and "read-only" in refused["error"]
            assert refused["time"].endswith("+00:00")
            listed = (await http(s.port, "GET", "/api/errors")).json()
            assert listed == [refused]
            overview = await stream.next("overview", lambda o: o["refused"] == 1)
            assert overview["refused"] == 1


@pytest.mark.asyncio
async def test_commissioning_runs_through_the_management_code(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as s:
        await both_online(s.port)
        scan = await http(s.port, "POST", "/api/request/device/scan", {"units": "1-6"})
        assert scan.status == 200 and scan.json()["status"] == "ok", scan.body
        found = {f["unit"]: f["device"] for f in scan.json()["data"]["found"]}
        assert found == {PUMP: "pump", STARTER: "starter"}
        body = {"bus": "tcp", "units": [PUMP, STARTER], "timeout": 0.3}
        identified = (await http(s.port, "POST", "/api/request/device/identify", body)).json()
        assert identified["status"] == "ok", identified
        summaries = {f["unit"]: f["summary"] for f in identified["data"]["found"]}
        assert summaries[STARTER].startswith("answers like Generic Motor soft-starter"), summaries
        assert set(summaries) == {PUMP, STARTER}

        body = {"bus": "tcp", "unit": STARTER, "address": 0x1001, "count": 2}
        read = (await http(s.port, "POST", "/api/request/device/read", body)).json()
        assert read["status"] == "ok", read
        expected = [s.sim.image(STARTER)[(Table.HOLDING, a)] for a in (0x1001, 0x1002)]
        assert read["data"]["registers"] == expected
        assert read["data"]["pairs"][0]["CDAB"]["u32"] == expected[1] << 16 | expected[0]

        secret = {"device": "pump", "address": 142, "count": 1}  # a password register
        refused = (await http(s.port, "POST", "/api/request/device/read", secret)).json()
        assert refused["status"] == "error" and "allow_raw_writes" in refused["error"]

        write = {"device": "pump", "address": 0x34, "values": [123]}
        off = (await http(s.port, "POST", "/api/request/device/write", write)).json()
        assert off == {
            "status": "error",
            "data": {},
            "error": "raw writes are off: set bridge.allow_raw_writes: true in the config",
            "transaction": None,
        }
        other = await http(s.port, "POST", "/api/request/mapping/reload", {})
        assert other.status == 404  # the page commissions; it does not reload mappings
        assert not s.sim.writes


@pytest.mark.asyncio
async def test_raw_writes_when_allowed_keep_the_dangerous_write_guard(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web.server")
    async with site(mosquitto, tmp_path, bridge={"allow_raw_writes": True}) as s:
        overview = await both_online(s.port)
        assert overview["raw_writes"] is True
        write = {"device": "pump", "address": 0x34, "values": [123]}
        done = (await http(s.port, "POST", "/api/request/device/write", write)).json()
        assert done["status"] == "ok", done
        assert s.sim.image(PUMP)[(Table.HOLDING, 0x34)] == 123
        assert "raw write from the web page (127.0.0.1)" in caplog.text  # the site's record
        rated = {"device": "pump", "address": 54, "values": [60]}  # rated motor frequency
        guarded = (await http(s.port, "POST", "/api/request/device/write", rated)).json()
        assert guarded["status"] == "error" and "allow_dangerous_writes" in guarded["error"]
        assert [w.address for _, w in s.sim.writes] == [0x34]


@pytest.mark.asyncio
async def test_a_token_guards_every_api_route_and_the_login_sets_a_cookie(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path, host="127.0.0.1", token=TOKEN) as s:
        page = await http(s.port, "GET", "/")
        assert page.status == 200 and b"<title>Modbus bridge</title>" in page.body
        for path in ("/api/overview", "/api/devices/pump", "/api/errors", "/api/config"):
            assert (await http(s.port, "GET", path)).status == 401, path
        async with events(s.port) as stream:
            assert stream.status == 401
        scan = await http(s.port, "POST", "/api/request/device/scan", {"units": "1"})
        assert scan.status == 401

        bearer = {"Authorization": f"Bearer {TOKEN}"}
        assert (await http(s.port, "GET", "/api/overview", headers=bearer)).status == 200
        wrong = await http(s.port, "POST", "/api/login", {"token": TOKEN + "x"})
        assert wrong.status == 401 and "set-cookie" not in wrong.headers
        login = await http(s.port, "POST", "/api/login", {"token": TOKEN})
        assert login.status == 200
        cookie = login.headers["set-cookie"]
        assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and TOKEN not in cookie
        session = {"Cookie": cookie.partition(";")[0]}
        assert (await http(s.port, "GET", "/api/overview", headers=session)).status == 200
        async with events(s.port, headers=session) as stream:
            assert stream.status == 200
            await stream.next("overview")
        config = (await http(s.port, "GET", "/api/config", headers=session)).json()
        assert config["config"]["bridge"]["web"]["token"] == "**********"
        assert TOKEN not in json.dumps(config)


@pytest.mark.asyncio
async def test_requests_from_other_sites_are_refused(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path) as s:
        await both_online(s.port)
        rebound = await http(s.port, "GET", "/api/overview", headers={"Host": "evil.example"})
        assert rebound.status == 403  # DNS rebinding: another name pointed at 127.0.0.1
        scan = "/api/request/device/scan"
        plain = await http(s.port, "POST", scan, b"{}", {"Content-Type": "text/plain"})
        assert plain.status == 415  # a cross-site form can send text/plain, never JSON
        foreign = {"Origin": "http://evil.example"}
        assert (await http(s.port, "POST", scan, {"units": "1"}, foreign)).status == 403
        cross = {"Sec-Fetch-Site": "cross-site"}
        assert (await http(s.port, "POST", scan, {"units": "1"}, cross)).status == 403
        own = {"Origin": f"http://127.0.0.1:{s.port}", "Sec-Fetch-Site": "same-origin"}
        assert (await http(s.port, "POST", scan, {"units": "1"}, own)).status == 200
        assert (await http(s.port, "GET", scan)).status == 405


@pytest.mark.asyncio
async def test_home_assistant_ingress(mosquitto: Broker, tmp_path: Path) -> None:
    """The ingress proxy (here 127.0.0.2) needs no token; everyone else does; the page's
    base follows X-Ingress-Path, from the proxy only."""
    async with site(mosquitto, tmp_path, token=TOKEN, ingress_proxies=["127.0.0.2"]) as s:
        proxied = await http(s.port, "GET", "/api/overview", source="127.0.0.2")
        assert proxied.status == 200
        assert (await http(s.port, "GET", "/api/overview", source="127.0.0.1")).status == 401
        prefix = "/api/hassio_ingress/Zx_9-abc"
        ingress = {"X-Ingress-Path": prefix}
        page = await http(s.port, "GET", "/", headers=ingress, source="127.0.0.2")
        assert f'<base href="{prefix}/">'.encode() in page.body
        page = await http(s.port, "GET", "/", headers=ingress, source="127.0.0.1")
        assert b'<base href="./">' in page.body  # not the proxy: its header is not taken
        for hostile in ('/x"><script>alert(1)</script>', "//evil.example", "/a/../b", "x"):
            headers = {"X-Ingress-Path": hostile}
            page = await http(s.port, "GET", "/", headers=headers, source="127.0.0.2")
            assert b'<base href="./">' in page.body, hostile
        scan = {"units": "1", "transaction": 7}
        headers = {"Origin": "http://homeassistant.local:8123"}  # HA's origin, not ours
        answer = await http(
            s.port, "POST", "/api/request/device/scan", scan, headers, source="127.0.0.2"
        )
        assert answer.json()["transaction"] == 7


@pytest.mark.asyncio
async def test_static_files_and_http_errors(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path) as s:
        page = await http(s.port, "GET", "/")
        assert page.headers["content-type"] == "text/html; charset=utf-8"
        assert "default-src 'self'" in page.headers["content-security-policy"]
        assert b'<base href="./">' in page.body
        script = await http(s.port, "GET", "/app.js")
        assert script.status == 200 and script.headers["content-type"].startswith("text/javascript")
        style = await http(s.port, "GET", "/style.css")
        assert style.status == 200 and b"prefers-color-scheme" in style.body
        head = await http(s.port, "HEAD", "/style.css")
        assert head.status == 200 and head.body == b"" and head.headers["content-length"]
        assert (await http(s.port, "GET", "/../pyproject.toml")).status == 404
        assert (await http(s.port, "GET", "/api/nothing")).status == 404
        assert (await http(s.port, "DELETE", "/")).status == 405
        assert (await http(s.port, "HEAD", "/api/events")).status == 405


@pytest.mark.asyncio
async def test_web_port_in_use_is_a_clear_error(mosquitto: Broker, tmp_path: Path) -> None:
    port = free_port()
    blocker = await asyncio.start_server(lambda r, w: w.close(), "127.0.0.1", port)
    data = {
        "mqtt": {"url": mosquitto.url},
        "bridge": {"web": {"enabled": True, "port": port}},
        "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": 1}],
    }
    bridge = Bridge(load_config_data(data, tmp_path / "config.yaml"))
    try:
        with pytest.raises(OSError, match=f"web page: cannot listen on 127.0.0.1:{port}"):
            await asyncio.wait_for(bridge.run(), 10)
    finally:
        blocker.close()


def test_the_page_off_imports_no_server_code() -> None:
    code = (
        "import sys, bridge.app, bridge.cli; "
        "print(sorted(m for m in sys.modules if m.startswith('bridge.web')))"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert loaded.stdout.strip() == "['bridge.web', 'bridge.web.live']"


@pytest.mark.asyncio
async def test_the_demo_prints_the_page_url_and_serves_the_five_devices(
    mosquitto: Broker,
) -> None:
    with demo("--mqtt-url", mosquitto.url) as process:
        lines = await read_until(process, "ready:")
        (shown,) = [line for line in lines if line.startswith("web page: ")]
        url = urlsplit(shown.removeprefix("web page: "))
        assert url.hostname == "127.0.0.1" and url.path == "/" and url.port
        overview = (await http(url.port, "GET", "/api/overview")).json()
        assert {d["id"] for d in overview["devices"]} == {seed.id for seed in SEEDS}
        assert (await http(url.port, "GET", "/")).status == 200
        await stop(process)
