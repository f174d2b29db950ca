"""The page's "Add a device" API on a running bridge (real Mosquitto, the simulator behind):
the host's ports, the library searched, scan, identify and a trial poll on a configured
bus and on a bus not configured yet; nothing saved, published or written.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from bridge.config import MqttConfig
from bridge.core.mapping import builtin_mapping_names, shipped_library
from bridge.errors import ValueRejectedError
from bridge.modbus.commission import raw_write
from bridge.modbus.ports import serial_ports
from bridge.modbus.simulator import Quirks
from bridge.modbus.trial import ReadsOnly
from bridge.mqtt import MqttClient
from bridge.web.http import BODY_LIMIT
from bridge.web.library import MAX_RESULTS
from tests.integration.harness import eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.web import (
    PUMP,
    STARTER,
    TOKEN,
    Answer,
    http,
    parse_answer,
    request_bytes,
    site,
)

NEW_UNIT = 5  # the unit on the bus not configured yet


@contextlib.asynccontextmanager
async def new_bus() -> AsyncIterator[tuple[object, dict[str, object]]]:
    """A second simulated gateway no bus of the config names: a pump at ``NEW_UNIT``."""
    sim = simulator((NEW_UNIT, "nastec_vasco"))
    sim.set_value(NEW_UNIT, "modbus_address", NEW_UNIT)  # what its fingerprint checks
    async with serving_tcp(sim) as port:
        yield sim, {"transport": "tcp", "host": "127.0.0.1", "tcp_port": port, "timeout": 0.3}


@pytest.mark.asyncio
async def test_the_hosts_ports_and_the_library_searched(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path) as s:
        ports = (await http(s.port, "GET", "/api/ports")).json()
        assert ports == {"ports": [p.as_dict() for p in serial_ports()]}

        everything = (await http(s.port, "GET", "/api/library")).json()
        assert everything["total"] == len(builtin_mapping_names())
        assert len(everything["mappings"]) == min(MAX_RESULTS, everything["total"])
        found = (await http(s.port, "GET", "/api/library?q=nastec%20MIDA")).json()
        assert [m["mapping"] for m in found["mappings"]] == ["nastec_vasco"]
        assert found["mappings"][0]["category"] == "pump"
        assert found["mappings"][0]["manufacturer"] == "Nastec"
        assert found["mappings"][0]["options"]["family"]["choices"] == ["vasco", "mida"]
        meters = (await http(s.port, "GET", "/api/library?q=METER")).json()
        assert meters["total"] > 1
        assert all(
            m["category"] == "meter" or "meter" in str(m).lower() for m in meters["mappings"]
        )
        none = (await http(s.port, "GET", "/api/library?q=no-such-device")).json()
        assert none == {"query": "no-such-device", "total": 0, "mappings": []}


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_scan_identify_and_try_on_a_configured_bus(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with site(mosquitto, tmp_path) as s:
        scan = await http(s.port, "POST", "/api/add/scan", {"bus": "tcp", "units": "1-6"})
        assert scan.status == 200, scan.body
        found = {f["unit"]: f["device"] for f in scan.json()["data"]["found"]}
        assert found == {PUMP: "pump", STARTER: "starter"}
        assert "scanned 6 units on bus tcp: 2 answered (127.0.0.1)" in caplog.text

        body = {"bus": "tcp", "units": [STARTER], "timeout": 0.3}
        identified = (await http(s.port, "POST", "/api/add/identify", body)).json()["data"]
        (starter,) = identified["found"]
        assert starter["summary"].startswith("answers like Generic Motor soft-starter")

        devices = set(s.bridge.engine.devices)
        async with watching_mqtt(mosquitto) as topics:
            ask = {"bus": "tcp", "unit": STARTER, "mapping": "soft_starter", "id": "new_starter"}
            trial = await http(s.port, "POST", "/api/trial", ask)
            assert trial.status == 200, trial.body
            seen = await topics()
        data = trial.json()["data"]
        values = {v["key"]: v for v in data["values"]}
        assert data["read"] > 0 and data["note"] is None and data["refused"] == []
        poller = s.bridge.engine.devices["starter"]  # the same device, polled by the bridge
        for key, value in poller.values.items():
            if key in values and values[key]["value"] is not None and isinstance(value, str):
                assert values[key]["value"] == value, key  # labels decode the same
        assert any(v["unit"] for v in data["values"] if v["value"] is not None)
        assert set(s.bridge.engine.devices) == devices  # nothing added to the running bridge
        assert not [t for t in seen if "new_starter" in t]  # nothing published
        assert not s.sim.writes
        # and were a trial poller ever to write, its scheduler would refuse it unsent
        reads_only = ReadsOnly(s.bridge.engine.schedulers["tcp"])
        with pytest.raises(ValueRejectedError, match="only reads"):
            await reads_only.submit(STARTER, raw_write("holding", 0x1001, [1]), timeout=1.0)
        assert not s.sim.writes


@contextlib.asynccontextmanager
async def watching_mqtt(broker: Broker) -> AsyncIterator[object]:
    """The topics the broker delivers meanwhile; ``await topics()`` ends the watch once a
    marker published after the block's work has come back (the broker's queue drained)."""
    seen: list[str] = []
    async with MqttClient(MqttConfig(url=broker.url), will_topic="watch/state") as client:
        await client.subscribe("#")
        marker = asyncio.Event()

        async def collect() -> None:
            async for message in client.messages():
                seen.append(message.topic)
                if message.topic == "watch/marker":
                    marker.set()

        task = asyncio.create_task(collect())

        async def topics() -> list[str]:
            await client.publish("watch/marker", "1")
            async with asyncio.timeout(10):
                await marker.wait()
            return seen

        try:
            yield topics
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_a_bus_not_configured_yet_is_opened_for_each_request_only(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as s, new_bus() as (sim, bus):
        scan = await http(s.port, "POST", "/api/add/scan", {"bus": bus, "units": "1-6"})
        assert scan.status == 200, scan.body
        data = scan.json()["data"]
        assert data["bus"] == "new" and [f["unit"] for f in data["found"]] == [NEW_UNIT]
        assert not s.bridge.engine.devices.keys() - {"pump", "starter"}

        body = {"bus": bus, "units": [NEW_UNIT]}
        identified = (await http(s.port, "POST", "/api/add/identify", body)).json()["data"]
        (pump,) = identified["found"]
        assert pump["matches"] and pump["matches"][0]["mapping"] == "nastec_vasco", pump

        dc_bus = shipped_library()["nastec_vasco"].points({})["dc_bus_voltage"]
        sim.set_quirks(NEW_UNIT, Quirks(refused=frozenset({dc_bus.address})))
        ask = {"bus": bus, "unit": NEW_UNIT, "mapping": "nastec_vasco", "name": "Well pump"}
        trial = await http(s.port, "POST", "/api/trial", ask)
        assert trial.status == 200, trial.body
        result = trial.json()["data"]
        assert result["bus"] == "new" and result["read"] > 0
        current = next(v for v in result["values"] if v["key"] == "motor_current")
        assert current["unit"] == "A" and current["value"] == pytest.approx(
            sim.value(NEW_UNIT, "motor_current")
        )
        assert {"table": "holding", "address": dc_bus.address} in result["refused"]
        assert next(v for v in result["values"] if v["key"] == "dc_bus_voltage")["value"] is None
        assert not sim.writes and not s.sim.writes

        silent = {**ask, "unit": NEW_UNIT + 1}
        nobody = (await http(s.port, "POST", "/api/trial", silent)).json()["data"]
        assert nobody["read"] == 0 and nobody["note"] == f"unit {NEW_UNIT + 1} did not answer"


SCAN, IDENTIFY, TRIAL = "/api/add/scan", "/api/add/identify", "/api/trial"
GOOD_TRIAL = {"bus": "tcp", "unit": STARTER, "mapping": "soft_starter"}
NEW = "NEW"  # stands for the new bus's settings in a row
# Hostile input for every new endpoint: (path, body, headers, status, what the answer says).
# Each is refused with its status and one log line, before anything reaches a bus.
HOSTILE = [
    pytest.param(SCAN, b"{not json", {}, 400, "not JSON", id="scan-bad-json"),
    pytest.param(SCAN, b"[1, 2]", {}, 400, "JSON object", id="scan-not-an-object"),
    pytest.param(SCAN, {"bus": "tcp", "units": 5}, {}, 400, "units", id="scan-units-wrong-type"),
    pytest.param(SCAN, {"bus": "tcp", "units": "0-300"}, {}, 400, "1..247", id="scan-bad-units"),
    pytest.param(SCAN, {"bus": "tcp", "units": "1-100000000000"}, {}, 400, "1..247", id="scan-huge-range"),
    pytest.param(SCAN, {"bus": "tcp", "units": list(range(1, 300))}, {}, 400, "units", id="scan-unit-list-too-long"),
    pytest.param(SCAN, {"bus": "tcp", "units": "1", "timeout": 99}, {}, 400, "timeout", id="scan-long-timeout"),
    pytest.param(SCAN, {"bus": "nope", "units": "1"}, {}, 404, "no bus 'nope'", id="scan-no-such-bus"),
    pytest.param(SCAN, {"bus": 5, "units": "1"}, {}, 400, "bus", id="scan-bus-wrong-type"),
    pytest.param(SCAN, {"bus": "tcp", "units": "1", "extra": 1}, {}, 400, "extra", id="scan-unknown-field"),
    pytest.param(SCAN, {"bus": {"transport": "rtu", "port": "/dev/ttyNOPE9"}, "units": "1"}, {}, 404, "no serial port", id="scan-port-that-does-not-exist"),
    pytest.param(SCAN, {"bus": {"transport": "rtu", "port": "/etc/passwd"}, "units": "1"}, {}, 404, "no serial port", id="scan-a-file-as-port"),
    pytest.param(SCAN, {"bus": {"transport": "rtu", "port": "/dev/x" * 100}, "units": "1"}, {}, 400, "255", id="scan-long-port"),
    pytest.param(SCAN, {"bus": {"transport": "rtu", "port": "/dev/ttyS0", "baudrate": 1}, "units": "1"}, {}, 400, "baudrate", id="scan-bad-baudrate"),
    pytest.param(SCAN, {"bus": {"transport": "tcp", "host": "127.0.0.1", "tcp_port": 70000}, "units": "1"}, {}, 400, "tcp_port", id="scan-bad-tcp-port"),
    pytest.param(SCAN, {"bus": {"transport": "tcp", "host": "h", "shell": "rm"}, "units": "1"}, {}, 400, "unknown fields", id="scan-new-bus-unknown-field"),
    pytest.param(SCAN, {"bus": {"transport": "tcp", "host": "h", "timeout": 600}, "units": "1"}, {}, 400, "timeout", id="scan-new-bus-long-timeout"),
    pytest.param(SCAN, {"bus": "CONFIGURED", "units": "1"}, {}, 409, "pick that bus", id="scan-a-configured-gateway-as-new"),
    pytest.param(SCAN, {"bus": "tcp", "units": "1"}, {"Content-Type": "text/plain"}, 415, "JSON", id="scan-text-plain"),
    pytest.param(SCAN, {"bus": "tcp", "units": "1"}, {"Origin": "http://evil.example"}, 403, "other sites", id="scan-other-origin"),
    pytest.param(SCAN, {"bus": "tcp", "units": "1"}, {"Sec-Fetch-Site": "cross-site"}, 403, "other sites", id="scan-cross-site"),
    pytest.param(IDENTIFY, {"bus": "tcp", "units": "x"}, {}, 400, "units", id="identify-bad-units"),
    pytest.param(IDENTIFY, {"bus": "tcp", "units": [0]}, {}, 400, "1..247", id="identify-unit-0"),
    pytest.param(TRIAL, GOOD_TRIAL | {"unit": 0}, {}, 400, "unit", id="trial-unit-0"),
    pytest.param(TRIAL, GOOD_TRIAL | {"unit": 300}, {}, 400, "unit", id="trial-unit-300"),
    pytest.param(TRIAL, GOOD_TRIAL | {"unit": "3"}, {}, 400, "unit", id="trial-unit-as-text"),
    pytest.param(TRIAL, GOOD_TRIAL | {"unit": True}, {}, 400, "unit", id="trial-unit-as-bool"),
    pytest.param(TRIAL, GOOD_TRIAL | {"mapping": "nope"}, {}, 404, "no shipped mapping", id="trial-no-such-mapping"),
    pytest.param(TRIAL, GOOD_TRIAL | {"mapping": "../../etc/passwd"}, {}, 404, "no shipped mapping", id="trial-mapping-path"),
    pytest.param(TRIAL, GOOD_TRIAL | {"id": "pump"}, {}, 409, "exists already", id="trial-id-collision"),
    pytest.param(TRIAL, GOOD_TRIAL | {"id": "Bad Id!"}, {}, 400, "id", id="trial-bad-id"),
    pytest.param(TRIAL, GOOD_TRIAL | {"name": "n" * 1_000_000}, {}, 413, "", id="trial-1-MB-name"),
    pytest.param(TRIAL, GOOD_TRIAL | {"name": "n" * 1000}, {}, 400, "name", id="trial-long-name"),
    pytest.param(TRIAL, GOOD_TRIAL | {"options": {"a": 1}}, {}, 400, "options", id="trial-option-wrong-type"),
    pytest.param(TRIAL, GOOD_TRIAL | {"options": {"no_such": "x"}}, {}, 400, "no such option", id="trial-unknown-option"),
    pytest.param(TRIAL, GOOD_TRIAL | {"bus": NEW, "unit": 256}, {}, 400, "unit", id="trial-new-bus-unit-256"),
    pytest.param(TRIAL, GOOD_TRIAL | {"bus": NEW, "mapping": "p2_vfd", "id": "starter"}, {}, 409, "exists already", id="trial-new-bus-id-collision"),
    pytest.param(TRIAL, GOOD_TRIAL | {"password": "x"}, {}, 400, "password", id="trial-password"),
    pytest.param(TRIAL, GOOD_TRIAL, {"Origin": "http://evil.example"}, 403, "other sites", id="trial-other-origin"),
    pytest.param(TRIAL, None, {}, 405, "POST only", id="trial-get"),
    pytest.param("/api/library?q=" + "x" * 200, None, {}, 400, "at most", id="library-long-query"),
    pytest.param("/api/library?q=" + "+".join("abcdefghij"), None, {}, 400, "words", id="library-many-words"),
]  # fmt: skip


@pytest.mark.asyncio
@pytest.mark.timeout(120)
async def test_hostile_input_to_every_new_endpoint(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with site(mosquitto, tmp_path) as s, new_bus() as (sim, bus):
        configured = s.bridge.loaded.config.buses[0]
        gateway = {"transport": "tcp", "host": configured.host, "tcp_port": configured.tcp_port}
        for row in HOSTILE:
            path, body, headers, status, said = row.values
            if isinstance(body, dict) and body.get("bus") in ("CONFIGURED", NEW):
                body = body | {"bus": gateway if body["bus"] == "CONFIGURED" else bus}
            before = len(web_lines(caplog))
            method = "GET" if body is None else "POST"
            answer = await ask(s.port, method, path, body, headers)
            assert answer.status == status, (row.id, answer.body[:300])
            if said:
                assert said in answer.json()["error"], (row.id, answer.body[:300])
            lines = web_lines(caplog)[before:]
            assert len(lines) == 1, (row.id, [r.getMessage() for r in lines])
            assert len(lines[0].getMessage()) < 600, row.id  # no 1 MB log line either
            assert not sim.requests and not s.sim.writes, row.id  # none sent there, none written


async def ask(port: int, method: str, path: str, body: object, headers: dict[str, str]) -> Answer:
    """``http``, but a body over the server's limit is announced and not sent: the server
    answers 413 from the head (sent whole, its unread bytes would reset the connection)."""
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    if len(data) <= BODY_LIMIT:
        return await http(port, method, path, body, headers)
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        head = request_bytes(method, path, port, b"", headers)
        head = head.replace(b"Content-Length: 0", f"Content-Length: {len(data)}".encode())
        writer.write(head)
        async with asyncio.timeout(10):
            return parse_answer(await reader.read(-1))
    finally:
        writer.close()


def web_lines(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name.startswith("bridge.web")]


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_new_bus_serves_one_request_at_a_time_and_is_closed_after_it(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as s, new_bus() as (sim, bus):
        # unit 5 answers first, then 35 silent units: the scan holds the bus 3.5 s at least
        long = {"bus": bus, "units": f"{NEW_UNIT}-40", "timeout": 0.1}
        first = asyncio.create_task(http(s.port, "POST", SCAN, long))
        await eventually(lambda: sim.requests, timeout=10)
        ask = {"bus": bus, "unit": NEW_UNIT, "mapping": "nastec_vasco"}
        second = await http(s.port, "POST", TRIAL, ask)
        assert second.status == 429 and "another request uses this bus" in second.json()["error"]
        device = {"id": "well", "bus": "gw", "unit": NEW_UNIT, "mapping": "nastec_vasco"}
        save = {"device": device, "bus": {"id": "gw", **bus}}  # the bridge would open it too
        saving = await http(s.port, "POST", "/api/config/devices", save)
        assert saving.status == 429 and "a request uses this bus" in saving.json()["error"]
        done = await first
        assert done.status == 200, done.body
        assert [f["unit"] for f in done.json()["data"]["found"]] == [NEW_UNIT]
        again = await http(s.port, "POST", TRIAL, ask)  # closed after the scan: free again
        assert again.status == 200 and again.json()["data"]["read"] > 0


@pytest.mark.asyncio
async def test_behind_ingress_the_log_names_the_home_assistant_user(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with site(mosquitto, tmp_path, token=TOKEN, ingress_proxies=["127.0.0.2"]) as s:
        user = {"X-Remote-User-Name": "alice", "Origin": "http://homeassistant.local:8123"}
        scan = {"bus": "tcp", "units": [STARTER]}
        proxied = await http(s.port, "POST", SCAN, scan, user, source="127.0.0.2")
        assert proxied.status == 200, proxied.body
        assert "scanned unit 3 on bus tcp: 1 answered (alice via ingress)" in caplog.text
        # a user header from anyone else is not believed (nor is the request let in)
        claimed = await http(s.port, "POST", SCAN, scan, user, source="127.0.0.1")
        assert claimed.status == 401
        bearer = {"Authorization": f"Bearer {TOKEN}", "X-Remote-User-Name": "mallory"}
        direct = await http(s.port, "POST", SCAN, scan, bearer, source="127.0.0.1")
        assert direct.status == 200
        assert "mallory" not in caplog.text and "1 answered (127.0.0.1)" in caplog.text
