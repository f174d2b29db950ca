"""A running bridge started from a config file with comments, its page on with a token,
three simulated devices on loopback TCP and a real Mosquitto: what the page's edits
(bridge/web/device_edits.py) change, and what they must leave alone."""

from __future__ import annotations

import asyncio
import contextlib
import difflib
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from bridge.app import Bridge
from bridge.config import load_config
from tests.integration import reconfigure_site
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.reconfigure_site import observing, published, unit_simulator
from tests.integration.web import TOKEN, Answer, http, listening
from tests.ports import free_port

AUTH = {"Authorization": f"Bearer {TOKEN}"}
INGRESS = "127.0.0.2"  # the ingress proxy's address in this config
DEVICES = ("pump", "drive", "starter")
CONFIG = """\
# The cabinet's bridge (a test's config: the page edits it, comments stay)
mqtt:
  url: {mqtt}   # the test broker
  command_expiry: 3

bridge:
  web:
    enabled: true
    host: 127.0.0.1
    port: {web}
    token: {token}
    ingress_proxies: [{ingress}]

buses:
  # the simulator on loopback
  - id: tcp
    transport: tcp
    host: 127.0.0.1
    tcp_port: {modbus}
    timeout: 0.5
{serial_bus}
devices:
  # the borehole's pump
  - id: pump
    name: Borehole pump   # as Home Assistant shows it
    bus: tcp
    unit: 1
    mapping: nastec_vasco
    poll: {{fast: 0.5, slow: 5}}

  - id: drive   # the conveyor's drive
    bus: tcp
    unit: 2
    mapping: vacon_nx
    poll: {{fast: 0.5, slow: 5}}

  # the soft starter of the main motor
  - id: starter
    bus: tcp
    unit: 3
    mapping: soft_starter
    poll:
      fast: 0.5   # every half second
      slow: 5
{serial_device}"""
SERIAL_BUS = """\
  - id: rs485   # a line with no adapter plugged in yet
    transport: rtu
    port: /dev/ttyNOPE0
"""
SERIAL_DEVICE = """\
  - id: meter
    bus: rs485
    unit: 7
    mapping: nastec_vasco
    enabled: false
"""


@dataclass
class EditSite(reconfigure_site.Site):
    """``reconfigure_site.Site`` (so ``Untouched`` measures it) with the page's port and
    the config file's text as written."""

    port: int = 0
    original: str = ""

    async def edit(self, device_id: str, body: object, **headers: str) -> Answer:
        return await http(
            self.port, "POST", f"/api/config/devices/{device_id}", body, AUTH | headers
        )

    async def remove(self, device_id: str) -> Answer:
        return await http(self.port, "POST", f"/api/config/devices/{device_id}/remove", {}, AUTH)

    async def get(self, path: str) -> Answer:
        return await http(self.port, "GET", path, None, AUTH)

    def diff(self) -> tuple[list[str], list[str]]:
        """The lines the config file lost and gained since the start."""
        now = self.path.read_text(encoding="utf-8")
        lines = difflib.ndiff(self.original.splitlines(), now.splitlines())
        rows = [line for line in lines if line[:2] in ("- ", "+ ")]
        return [r[2:] for r in rows if r[0] == "-"], [r[2:] for r in rows if r[0] == "+"]


@contextlib.asynccontextmanager
async def edit_site(
    broker: Broker, folder: Path, *, serial: bool = False
) -> AsyncIterator[EditSite]:
    """The bridge on ``CONFIG`` (file ``folder/config.yaml``), every device published;
    with ``serial``, a serial bus and a disabled device on it too."""
    sim = unit_simulator()
    async with contextlib.AsyncExitStack() as stack:
        modbus = await stack.enter_async_context(serving_tcp(sim))
        port = free_port()
        text = CONFIG.format(
            mqtt=broker.url, web=port, token=TOKEN, ingress=INGRESS, modbus=modbus,
            serial_bus=SERIAL_BUS if serial else "", serial_device=SERIAL_DEVICE if serial else "",
        )  # fmt: skip
        path = folder / "config.yaml"
        path.write_text(text, encoding="utf-8")
        observer = await stack.enter_async_context(
            observing(broker, "observer", "modbus/#", "homeassistant/device/+/config")
        )
        bridge = Bridge(await asyncio.to_thread(load_config, path))
        task = asyncio.create_task(bridge.run())
        stack.push_async_callback(cancel, task)
        await listening(port)
        here = EditSite(broker, bridge, sim, {}, path, observer, {"tcp": modbus}, port, text)
        await eventually(lambda: published(here, list(DEVICES)), timeout=15)
        yield here


def web_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    """What the page's modules logged (the HTTP server's refusals too)."""
    return [r.getMessage() for r in caplog.records if r.name.startswith("bridge.web")]


def folder_files(folder: Path) -> dict[str, bytes]:
    """Every file of the config's folder (backups would show here)."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def discovery(here: EditSite, device_id: str) -> dict[str, Any]:
    return here.observer.json(f"homeassistant/device/{device_id}/config")
