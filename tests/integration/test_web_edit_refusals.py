"""Hostile input to the page's device edits (bridge/web/device_edits.py) on a running
bridge: each row gets its status and a message naming what is wrong, one log line, and
nothing written (the config folder's bytes unchanged, no backup) or applied."""

from __future__ import annotations

import asyncio
import json
import logging
from pathlib import Path
from typing import Any

import pytest

from bridge.web import edit_request
from bridge.web.http import BODY_LIMIT
from tests.integration.mosquitto import Broker
from tests.integration.web import Answer, demo_site, http, parse_answer, request_bytes
from tests.integration.web_edit_site import (
    AUTH,
    EditSite,
    edit_site,
    folder_files,
    web_lines,
)

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(120)]
PUMP = "/api/config/devices/pump"
DRIVE = "/api/config/devices/drive"
DANGER = {"allow_dangerous_writes": True}
EVIL = "http://evil.example"
# (method, path, body, headers, status, what the error says); a "confirmation" of EXPIRED,
# OTHER_CHANGE or OTHER_DEVICE is a token the page was given for that (see ``token_for``)
EXPIRED, OTHER_CHANGE, OTHER_DEVICE = "<expired>", "<other change>", "<other device>"
HOSTILE = [
    pytest.param("POST", PUMP, {"unit": 0}, {}, 400, "unit", id="unit-0"),
    pytest.param("POST", PUMP, {"unit": 256}, {}, 400, "unit", id="unit-256"),
    pytest.param("POST", "/api/config/devices/meter", {"unit": 248}, {}, 400, "serial lines address units 1..247", id="serial-unit-248"),
    pytest.param("POST", PUMP, {"unit": "4"}, {}, 400, "unit", id="unit-as-text"),
    pytest.param("POST", PUMP, {"unit": True}, {}, 400, "unit", id="unit-as-bool"),
    pytest.param("POST", PUMP, {"unit": 4.0}, {}, 400, "unit", id="unit-as-float"),
    pytest.param("POST", PUMP, {"unit": 3}, {}, 409, "unit 3 on bus tcp is 'starter' already", id="unit-collision"),
    pytest.param("POST", PUMP, {"id": "starter"}, {}, 409, "'starter' exists already", id="id-collision"),
    pytest.param("POST", PUMP, {"id": "Bad Id!"}, {}, 400, "id", id="bad-id"),
    pytest.param("POST", PUMP, {"id": "x" * 65}, {}, 400, "id", id="long-id"),
    pytest.param("POST", PUMP, {"name": "n" * 1_000_000}, {}, 413, "", id="1-MB-name"),
    pytest.param("POST", PUMP, {"name": "n" * 101}, {}, 400, "name", id="long-name"),
    pytest.param("POST", PUMP, {"name": "a\nb: c"}, {}, 400, "control characters", id="name-with-a-line-break"),
    pytest.param("POST", PUMP, {"name": 5}, {}, 400, "name", id="name-as-number"),
    pytest.param("POST", PUMP, b"{not json", {}, 400, "not JSON", id="bad-json"),
    pytest.param("POST", PUMP, b"\xff\xfe", {}, 400, "not JSON", id="not-utf8"),
    pytest.param("POST", PUMP, [{"name": "x"}], {}, 400, "JSON object", id="json-list"),
    pytest.param("POST", PUMP, {}, {}, 400, "nothing to change", id="empty-object"),
    pytest.param("POST", PUMP, {"enabled": "yes"}, {}, 400, "enabled", id="enabled-as-text"),
    pytest.param("POST", PUMP, {"poll": {"fast": -1}}, {}, 400, "poll.fast", id="negative-interval"),
    pytest.param("POST", PUMP, {"poll": {"fast": 1e300}}, {}, 400, "poll.fast", id="huge-interval"),
    pytest.param("POST", PUMP, {"poll": {"fast": "soon"}}, {}, 400, "poll.fast", id="interval-not-a-duration"),
    pytest.param("POST", PUMP, {"poll": {"fast": None}}, {}, 400, "poll", id="interval-null"),
    pytest.param("POST", PUMP, {"poll": 5}, {}, 400, "poll", id="poll-not-an-object"),
    pytest.param("POST", PUMP, {"poll": {"entities": {"x": "fast"}}}, {}, 400, "not a field", id="poll-entities"),
    pytest.param("POST", PUMP, {"mapping": "p2_vfd"}, {}, 400, "not a field", id="mapping"),
    pytest.param("POST", PUMP, {"bus": "rs485"}, {}, 400, "not a field", id="bus"),
    pytest.param("POST", PUMP, {"password": "1234"}, {}, 400, "not a field", id="password"),
    pytest.param("POST", PUMP, {"allow_raw_writes": True}, {}, 400, "not a field", id="raw-writes"),
    pytest.param("POST", PUMP, {"bridge": {"allow_raw_writes": True}}, {}, 400, "not a field", id="bridge-raw-writes"),
    pytest.param("POST", PUMP, {"gateway_raw_writes": True}, {}, 400, "not a field", id="gateway-raw-writes"),
    pytest.param("POST", PUMP, {"allow_dangerous_writes": "true"}, {}, 400, "allow_dangerous_writes", id="dangerous-as-text"),
    pytest.param("POST", "/api/config/devices/nope", {"name": "x"}, {}, 404, "no such device", id="unknown-device"),
    pytest.param("POST", "/api/config/devices/nope/remove", {}, {}, 404, "no such device", id="remove-unknown-device"),
    pytest.param("POST", "/api/config/devices/" + "x" * 300, {"name": "x"}, {}, 404, "no such device", id="long-id-in-path"),
    pytest.param("POST", PUMP + "/explode", {}, {}, 404, "no such API", id="unknown-action"),
    pytest.param("POST", DRIVE, DANGER, {}, 409, "confirm", id="dangerous-without-confirmation"),
    pytest.param("POST", DRIVE, DANGER | {"confirmation": "x" * 32}, {}, 409, "expired or was for another change", id="made-up-token"),
    pytest.param("POST", DRIVE, DANGER | {"confirmation": EXPIRED}, {}, 409, "expired", id="stale-token"),
    pytest.param("POST", DRIVE, DANGER | {"name": "Drive", "confirmation": OTHER_CHANGE}, {}, 409, "another change", id="token-of-another-change"),
    pytest.param("POST", "/api/config/devices/starter", DANGER | {"confirmation": OTHER_DEVICE}, {}, 409, "another change", id="token-of-another-device"),
    pytest.param("POST", DRIVE, DANGER | {"confirmation": "x" * 65}, {}, 400, "confirmation", id="long-token"),
    pytest.param("POST", PUMP, {"name": "x"}, {"Origin": EVIL}, 403, "other sites", id="cross-origin"),
    pytest.param("POST", PUMP, {"name": "x"}, {"Sec-Fetch-Site": "cross-site"}, 403, "other sites", id="cross-site"),
    pytest.param("POST", PUMP, {"name": "x"}, {"Content-Type": "text/plain"}, 415, "JSON", id="text-plain"),
    pytest.param("POST", PUMP, {"name": "x"}, {"Authorization": ""}, 401, "token", id="no-token"),
    pytest.param("POST", PUMP, {"name": "x"}, {"Authorization": "Bearer wrong-token-0123456789"}, 401, "token", id="wrong-token"),
    pytest.param("PUT", PUMP, {"name": "x"}, {}, 405, "POST", id="put"),
    pytest.param("DELETE", PUMP, {"name": "x"}, {}, 405, "POST", id="delete"),
]  # fmt: skip


async def test_hostile_input_to_the_edits(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with edit_site(mosquitto, tmp_path, serial=True) as here:
        files = folder_files(tmp_path)
        running = here.bridge.loaded
        pollers = dict(here.bridge.engine.devices)
        for row in HOSTILE:
            method, path, body, headers, status, said = row.values
            body = await with_token(here, body)
            before = len(web_lines(caplog))
            answer = await ask(here.port, method, path, body, AUTH | headers)
            assert answer.status == status, (row.id, answer.body[:300])
            if said:
                assert said in answer.json()["error"], (row.id, answer.body[:300])
            lines = web_lines(caplog)[before:]
            assert len(lines) == 1, (row.id, lines)
            assert len(lines[0]) < 600, row.id  # no 1 MB log line either
            assert folder_files(tmp_path) == files, row.id  # nothing written, no backup
            assert here.bridge.loaded is running, row.id  # nothing applied
            assert here.bridge.engine.devices == pollers, row.id


async def with_token(here: EditSite, body: Any) -> Any:
    """``body`` with a placeholder confirmation replaced by a token the page gave."""
    if not isinstance(body, dict) or body.get("confirmation") not in (
        EXPIRED,
        OTHER_CHANGE,
        OTHER_DEVICE,
    ):
        return body
    kind = body["confirmation"]
    if kind == EXPIRED:
        saved = edit_request.CONFIRM_FOR
        edit_request.CONFIRM_FOR = 0.0  # given already expired
        try:
            token = await token_for(here, "drive", DANGER)
        finally:
            edit_request.CONFIRM_FOR = saved
    else:  # a token for the drive's plain DANGER: another change, or another device
        token = await token_for(here, "drive", DANGER)
    return body | {"confirmation": token}


async def token_for(here: EditSite, device_id: str, body: dict[str, Any]) -> str:
    answer = await here.edit(device_id, body)
    assert answer.status == 409, answer.body
    token: str = answer.json()["token"]
    return token


async def ask(port: int, method: str, path: str, body: object, headers: dict[str, str]) -> Answer:
    """``http``, but a body over the server's limit is announced and not sent: the server
    answers 413 from the head (sent whole, its unread bytes would reset the connection)."""
    headers = {k: v for k, v in headers.items() if v}  # "": the header left out
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


async def test_a_confirmation_is_used_once(mosquitto: Broker, tmp_path: Path) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        token = await token_for(here, "drive", DANGER)
        first = await here.edit("drive", DANGER | {"confirmation": token})
        assert first.status == 200, first.body
        off = await here.edit("drive", {"allow_dangerous_writes": False})
        assert off.status == 200, off.body
        again = await here.edit("drive", DANGER | {"confirmation": token})
        assert again.status == 409 and "expired" in again.json()["error"]
        assert not here.bridge.engine.devices["drive"].device.allow_dangerous_writes


async def test_the_demo_s_config_is_no_file_the_page_writes(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with demo_site(mosquitto, tmp_path) as s:
        listed = (await http(s.port, "GET", "/api/config/devices")).json()
        assert listed["writable"] is False and len(listed["devices"]) == 5
        device = listed["devices"][0]["id"]
        one = (await http(s.port, "GET", f"/api/config/devices/{device}")).json()
        assert one["writable"] is False  # the Edit panel says so, its fields off
        before = len(web_lines(caplog))
        answer = await http(s.port, "POST", f"/api/config/devices/{device}", {"name": "x"})
        assert answer.status == 403, answer.body
        assert "built without a file" in answer.json()["error"]
        assert len(web_lines(caplog)[before:]) == 1
        assert s.bridge.loaded.config.devices[0].name != "x"
