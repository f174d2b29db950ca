"""The page's Save on a running bridge whose config is a real file with comments: the file
gets the device (and its new bus) and nothing else, the running bridge polls it at once,
the other devices keep polling; a file changed on disk is never overwritten; bad input
is refused with its status, one log line and the file untouched."""

from __future__ import annotations

import asyncio
import contextlib
import difflib
import logging
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import load_config
from tests.integration.harness import cancel, eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_web_add import NEW_UNIT, ask, new_bus, web_lines
from tests.integration.web import PUMP, STARTER, http, listening, site
from tests.ports import free_port

SAVE = "/api/config/devices"
CONFIG = """\
# The cabinet's bridge (a comment the page must keep)
mqtt:
  url: {broker}
  command_expiry: 3
bridge:
  scan_timeout: 0.1
  web: {{enabled: true, host: 127.0.0.1, port: {web}}}
buses:
  - id: tcp   # the panel's gateway
    transport: tcp
    host: 127.0.0.1
    tcp_port: {modbus}
    timeout: 0.3
devices:
  - id: pump
    bus: tcp
    unit: {pump}
    mapping: nastec_vasco
    poll: {{fast: 0.2, slow: 2}}
  # the starter, checked in May
  - id: starter
    bus: tcp
    unit: {starter}
    mapping: soft_starter
    poll: {{fast: 0.2, slow: 2}}
"""


@dataclass
class FileSite:
    bridge: Bridge
    port: int
    path: Path
    sim: Any


@contextlib.asynccontextmanager
async def file_site(broker: Broker, folder: Path) -> AsyncIterator[FileSite]:
    """The bridge of tests/integration/web.py, its config read from a commented file."""
    sim = simulator((PUMP, "nastec_vasco"), (STARTER, "soft_starter"), tick=0)
    port = free_port()
    async with serving_tcp(sim) as modbus_port:
        path = folder / "config.yaml"
        path.write_text(
            CONFIG.format(
                broker=broker.url, web=port, modbus=modbus_port, pump=PUMP, starter=STARTER
            )
        )
        running = Bridge(load_config(path))
        task = asyncio.create_task(running.run())
        try:
            await listening(port)
            yield FileSite(running, port, path, sim)
        finally:
            await cancel(task)


def added_lines(before: str, after: str) -> list[str]:
    """The lines ``after`` adds to ``before``; fails if it changed or removed any."""
    diff = list(difflib.ndiff(before.splitlines(), after.splitlines()))
    assert not [line for line in diff if line.startswith("- ")], diff
    return [line[2:] for line in diff if line.startswith("+ ")]


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_save_writes_the_device_and_its_new_bus_and_the_bridge_polls_it(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with file_site(mosquitto, tmp_path) as s, new_bus() as (sim, bus):
        before = s.path.read_text()
        pump = s.bridge.engine.devices["pump"]
        device = {"id": "well", "name": "Well pump", "bus": "gw2", "unit": NEW_UNIT}
        device |= {"mapping": "nastec_vasco", "options": {"family": "vasco"}}
        body = {"device": device, "bus": {"id": "gw2", **bus}}
        saved = await http(s.port, "POST", SAVE, body)
        assert saved.status == 200, saved.body
        assert saved.json()["data"]["applied"]["status"] == "ok"
        added = added_lines(before, s.path.read_text())  # comments and order kept
        assert "  - id: gw2" in added and "  - id: well" in added, added
        await eventually(lambda: s.bridge.engine.devices["well"].health.online, timeout=20)
        assert s.bridge.engine.devices["pump"] is pump  # untouched, still polling
        assert "saved and applied" in caplog.text and "add device well" in caplog.text
        assert "(127.0.0.1)" in caplog.text
        assert not sim.writes and not s.sim.writes


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_file_changed_on_disk_is_not_overwritten(mosquitto: Broker, tmp_path: Path) -> None:
    async with file_site(mosquitto, tmp_path) as s:
        first = {"device": {"id": "a1", "bus": "tcp", "unit": 9, "mapping": "soft_starter"}}
        assert (await http(s.port, "POST", SAVE, first)).status == 200  # the store has read it
        edited = s.path.read_text() + "# someone else's note\n"
        s.path.write_text(edited)
        second = {"device": {"id": "a2", "bus": "tcp", "unit": 10, "mapping": "soft_starter"}}
        conflict = await http(s.port, "POST", SAVE, second)
        assert conflict.status == 409, conflict.body
        assert "+# someone else's note" in conflict.json()["diff"]
        assert s.path.read_text() == edited
        again = await http(s.port, "POST", SAVE, second)  # redone on the file as it is now
        assert again.status == 200, again.body
        assert "# someone else's note" in s.path.read_text()


SAVE_HOSTILE = [
    pytest.param(b"{not json", 400, "not JSON", id="bad-json"),
    pytest.param({"device": {"id": "pump", "bus": "tcp", "unit": 9, "mapping": "soft_starter"}}, 400, "pump", id="id-collision"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": "9", "mapping": "soft_starter"}}, 400, "unit", id="unit-as-text"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": 0, "mapping": "soft_starter"}}, 400, "unit", id="unit-0"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": PUMP, "mapping": "soft_starter"}}, 400, "unit", id="unit-taken"),
    pytest.param({"device": {"id": "x", "bus": "nope", "unit": 9, "mapping": "soft_starter"}}, 404, "no bus", id="no-such-bus"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": 9, "mapping": "/etc/passwd"}}, 404, "no shipped mapping", id="mapping-path"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": 9, "mapping": "soft_starter", "password": "p"}}, 400, "password", id="a-secret"),
    pytest.param({"device": {"id": "Bad Id", "bus": "tcp", "unit": 9, "mapping": "soft_starter"}}, 400, "id", id="bad-id"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": 9, "mapping": "soft_starter"}, "extra": 1}, 400, "extra", id="unknown-field"),
    pytest.param([1], 400, "JSON object", id="not-an-object"),
    pytest.param({"device": {"id": "x", "bus": "gw", "unit": 9, "mapping": "soft_starter"}, "bus": {"id": "other", "transport": "tcp", "host": "h"}}, 400, "device.bus", id="new-bus-not-the-devices"),
    pytest.param({"device": {"id": "x", "bus": "gw", "unit": 9, "mapping": "soft_starter"}, "bus": {"id": "gw", "transport": "tcp", "host": "127.0.0.1", "tcp_port": "CONFIGURED"}}, 409, "pick that bus", id="new-bus-on-a-configured-gateway"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": 9, "mapping": "soft_starter", "allow_dangerous_writes": True}}, 400, "allow_dangerous_writes", id="dangerous-writes"),
    pytest.param({"device": {"id": "x", "bus": "tcp", "unit": 9, "mapping": "soft_starter", "name": "n" * 1_000_000}}, 413, "", id="1-MB-name"),
    pytest.param({"device": {"id": "x", "bus": "s1", "unit": 9, "mapping": "soft_starter"}, "bus": {"id": "s1", "transport": "rtu", "port": "/dev/ttyNOPE9"}}, 404, "no serial port", id="port-that-does-not-exist"),
]  # fmt: skip


@pytest.mark.asyncio
@pytest.mark.timeout(120)
async def test_hostile_saves_are_refused_with_one_log_line_and_nothing_written(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with file_site(mosquitto, tmp_path) as s:
        before = s.path.read_text()
        devices = set(s.bridge.engine.devices)
        configured = s.bridge.loaded.config.buses[0].tcp_port
        for row in SAVE_HOSTILE:
            body, status, said = row.values
            new = body.get("bus") if isinstance(body, dict) else None
            if isinstance(new, dict) and new.get("tcp_port") == "CONFIGURED":
                body = body | {"bus": new | {"tcp_port": configured}}
            count = len(web_lines(caplog))
            answer = await ask(s.port, "POST", SAVE, body, {})
            assert answer.status == status, (row.id, answer.body[:300])
            if said:
                assert said in answer.json()["error"], (row.id, answer.body[:300])
            lines = web_lines(caplog)[count:]
            assert len(lines) == 1, (row.id, [r.getMessage() for r in lines])
            assert len(lines[0].getMessage()) < 1000, row.id
            assert s.path.read_text() == before, row.id  # nothing written
            assert not list(tmp_path.glob("config.yaml.*")), row.id  # no backup either
            assert set(s.bridge.engine.devices) == devices, row.id
        assert not s.sim.writes


@pytest.mark.asyncio
async def test_a_config_that_is_no_file_is_not_saved_to(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with site(mosquitto, tmp_path) as s:  # its config is data: no file behind it
        body = {"device": {"id": "x", "bus": "tcp", "unit": 9, "mapping": "soft_starter"}}
        refused = await http(s.port, "POST", SAVE, body)
        assert refused.status == 403
        assert "built without a file (config.yaml is not there)" in refused.json()["error"]
        assert not (tmp_path / "config.yaml").exists()
        assert "x" not in s.bridge.engine.devices
