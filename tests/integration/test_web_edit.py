"""Edit and remove a configured device from the page (bridge/web/device_edits.py) on a
running bridge started from a commented config file: a real Mosquitto, three simulated
devices. Each change is answered with its summary, logged once, applied live (the other
devices keep their poller, their counters and their polls: ``Untouched``), and leaves the
config file the user's with that one change (comments kept).
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from bridge.web import edit_request
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.reconfigure_site import Untouched, published
from tests.integration.web import http
from tests.integration.web_edit_site import (
    AUTH,
    INGRESS,
    discovery,
    edit_site,
    web_lines,
)

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(120)]


def one_change_line(caplog: pytest.LogCaptureFixture, before: int) -> str:
    [line] = web_lines(caplog)[before:]
    return line


async def test_renamed_home_assistant_shows_the_new_name_the_others_poll_on(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with edit_site(mosquitto, tmp_path) as here:
        untouched = Untouched.of(here, "drive", "starter")
        before = len(web_lines(caplog))

        answer = await here.edit("pump", {"name": "Well pump"})

        assert answer.status == 200, answer.body
        body = answer.json()
        assert body["status"] == "ok" and body["device"] == "pump"
        assert body["changes"] == {"restarted": ["pump"]}
        assert 'devices.pump.name: "Borehole pump" -> "Well pump"' in body["summary"]
        line = one_change_line(caplog, before)
        assert line.endswith(
            'edit device pump; devices.pump.name: "Borehole pump" -> "Well pump" (127.0.0.1)'
        )
        await eventually(lambda: discovery(here, "pump")["device"]["name"] == "Well pump")
        assert here.diff() == (
            ["    name: Borehole pump   # as Home Assistant shows it"],
            ["    name: Well pump       # as Home Assistant shows it"],  # its column kept
        )
        await untouched.check()


async def test_moved_to_another_unit_it_is_polled_there(mosquitto: Broker, tmp_path: Path) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        untouched = Untouched.of(here, "drive", "starter")
        answer = await here.edit("pump", {"unit": 4})
        assert answer.status == 200, answer.body
        assert here.bridge.engine.devices["pump"].device.unit == 4
        await eventually(lambda: here.sim.reads(4))  # the pump at unit 4 answers now
        assert here.diff() == (["    unit: 1"], ["    unit: 4"])
        await untouched.check()


async def test_poll_intervals_changed_in_the_file_s_own_style(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        untouched = Untouched.of(here, "pump", "drive")
        answer = await here.edit("starter", {"poll": {"fast": 1, "slow": "30s"}})
        assert answer.status == 200, answer.body
        poll = here.bridge.engine.devices["starter"].device.poll
        assert (poll.fast, poll.slow) == (1.0, 30.0)
        assert here.diff() == (
            ["      fast: 0.5   # every half second", "      slow: 5"],
            ["      fast: 1     # every half second", "      slow: 30s"],
        )
        await untouched.check()
        untouched = Untouched.of(here, "drive")  # (the starter polls every second now)
        flow = await here.edit("pump", {"poll": {"fast": 2}})  # a flow mapping stays one
        assert flow.status == 200, flow.body
        lost, gained = here.diff()
        assert "    poll: {fast: 0.5, slow: 5}" in lost
        assert "    poll: {fast: 2, slow: 5}" in gained
        await untouched.check()


async def test_disabled_then_enabled_its_topics_go_and_come_back(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        retained = here.observer.retained
        untouched = Untouched.of(here, "pump", "drive")

        off = await here.edit("starter", {"enabled": False})

        assert off.status == 200, off.body
        assert off.json()["changes"] == {"disabled": ["starter"]}
        await eventually(lambda: retained.get("homeassistant/device/starter/config") == b"")
        await eventually(lambda: retained.get("modbus/starter") == b"")
        assert "starter" not in here.bridge.engine.devices
        listed = (await here.get("/api/config/devices")).json()
        row = next(d for d in listed["devices"] if d["id"] == "starter")
        assert (row["enabled"], row["polled"], listed["writable"]) == (False, False, True)
        assert here.diff() == ([], ["    enabled: false"])
        await untouched.check()

        on = await here.edit("starter", {"enabled": True})

        assert on.status == 200, on.body
        assert on.json()["changes"] == {"enabled": ["starter"]}
        await eventually(lambda: published(here, ["starter"]), timeout=10)
        assert here.diff() == ([], ["    enabled: true"])
        await untouched.check()


async def test_removed_its_discovery_and_retained_state_are_cleared(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with edit_site(mosquitto, tmp_path) as here:
        retained = here.observer.retained
        untouched = Untouched.of(here, "pump", "starter")
        before = len(web_lines(caplog))

        answer = await here.remove("drive")

        assert answer.status == 200, answer.body
        assert answer.json()["changes"] == {"removed": ["drive"]}
        assert answer.json()["device"] is None
        assert "remove device drive" in one_change_line(caplog, before)
        await eventually(lambda: retained.get("homeassistant/device/drive/config") == b"")
        await eventually(lambda: retained.get("modbus/drive") == b"")
        left = await here.retained_now(
            "modbus/drive", "modbus/drive/#", "homeassistant/device/drive/config"
        )
        assert left == {}
        lost, gained = here.diff()
        assert gained == []
        block = [
            "  - id: drive   # the conveyor's drive",
            "    bus: tcp",
            "    unit: 2",
            "    mapping: vacon_nx",
            "    poll: {fast: 0.5, slow: 5}",
        ]
        assert [line for line in lost if line.strip()] == block
        assert "  # the soft starter of the main motor" in here.path.read_text()
        assert (await here.get("/api/config/devices/drive")).status == 404
        await untouched.check()


async def test_dangerous_writes_need_their_own_confirmation(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with edit_site(mosquitto, tmp_path) as here:
        untouched = Untouched.of(here, "pump", "starter")
        listed = (await here.get("/api/config/devices/drive/dangerous")).json()
        names = [e["name"] for e in listed["entities"]]
        assert names == [
            "Reverse direction",
            "Speed reference",
            "Response to fieldbus fault",
            "Response to slot fault",
        ]
        speed = listed["entities"][1]
        assert speed["permits"] == "values below 0" and speed["component"] == "number"
        assert (listed["allowed"], listed["raw_writes"]) == (False, False)
        reverse = discovery(here, "drive")["cmps"]["reverse"]
        assert reverse["platform"] == "binary_sensor"  # shown read-only until allowed

        first = await here.edit("drive", {"allow_dangerous_writes": True})

        assert first.status == 409, first.body
        asked = first.json()
        assert asked["status"] == "confirm"
        assert [e["name"] for e in asked["entities"]] == names
        assert asked["expires_s"] == edit_request.CONFIRM_FOR
        assert not here.bridge.engine.devices["drive"].device.allow_dangerous_writes
        assert here.diff() == ([], [])
        assert "waits for its confirmation" in web_lines(caplog)[-1]
        assert "Reverse direction" in web_lines(caplog)[-1]

        confirmed = {"allow_dangerous_writes": True, "confirmation": asked["token"]}
        second = await here.edit("drive", confirmed)

        assert second.status == 200, second.body
        assert here.bridge.engine.devices["drive"].device.allow_dangerous_writes
        await eventually(
            lambda: discovery(here, "drive")["cmps"]["reverse"]["platform"] == "switch"
        )
        assert here.diff() == ([], ["    allow_dangerous_writes: true"])
        off = await here.edit("drive", {"allow_dangerous_writes": False})  # no step to turn off
        assert off.status == 200, off.body
        await untouched.check()


async def test_renamed_id_and_the_ingress_user_named_in_the_log(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web")
    async with edit_site(mosquitto, tmp_path) as here:
        retained = here.observer.retained
        untouched = Untouched.of(here, "pump", "drive")
        user = {"X-Remote-User-Name": "alice", "Origin": "http://homeassistant.local:8123"}
        before = len(web_lines(caplog))
        answer = await http(
            here.port, "POST", "/api/config/devices/starter", {"id": "main_starter"}, user,
            source=INGRESS,
        )  # fmt: skip
        assert answer.status == 200, answer.body
        assert answer.json()["device"] == "main_starter"
        assert "(alice via ingress)" in one_change_line(caplog, before)
        await eventually(lambda: published(here, ["main_starter"]), timeout=10)
        await eventually(lambda: retained.get("homeassistant/device/starter/config") == b"")
        assert here.diff() == (["  - id: starter"], ["  - id: main_starter"])
        await untouched.check()


async def test_a_file_changed_on_disk_is_not_overwritten(mosquitto: Broker, tmp_path: Path) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        by_hand = here.original.replace("timeout: 0.5", "timeout: 0.6")
        here.path.write_text(by_hand, encoding="utf-8")

        answer = await here.edit("pump", {"name": "Well pump"})

        assert answer.status == 409, answer.body
        assert "changed on disk" in answer.json()["error"]
        diff = answer.json()["diff"]
        assert "-    timeout: 0.5" in diff and "+    timeout: 0.6" in diff
        assert here.path.read_text(encoding="utf-8") == by_hand
        # until the bridge runs the file as it is, the page changes nothing
        again = await here.edit("pump", {"name": "Well pump"})
        assert again.status == 409, again.body
        assert (
            "holds changes the bridge does not run (buses restarted: tcp" in again.json()["error"]
        )
        assert here.path.read_text(encoding="utf-8") == by_hand
        here.bridge.hangup()  # SIGHUP: the bridge reads the file and applies it
        await eventually(lambda: here.bridge.loaded.config.buses[0].timeout == 0.6)
        third = await here.edit("pump", {"name": "Well pump"})
        assert third.status == 200, third.body
        assert third.json()["changes"] == {"restarted": ["pump"]}
        text = here.path.read_text(encoding="utf-8")
        assert "timeout: 0.6" in text and "name: Well pump" in text


async def test_the_page_reads_a_device_as_configured(mosquitto: Broker, tmp_path: Path) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        answer = await here.get("/api/config/devices/pump")
        assert answer.status == 200
        pump = answer.json()
        assert {k: pump[k] for k in ("id", "name", "bus", "unit", "max_unit", "enabled")} == {
            "id": "pump",
            "name": "Borehole pump",
            "bus": "tcp",
            "unit": 1,
            "max_unit": 255,
            "enabled": True,
        }
        assert pump["poll"] == {"fast": 0.5, "slow": 5.0}
        assert pump["writable"] is True
        assert pump["dangerous"]["entities"]  # the pump's settings
        unauthorised = await http(here.port, "GET", "/api/config/devices/pump")
        assert unauthorised.status == 401
        assert AUTH  # the others carry it


async def test_a_hand_edit_the_bridge_runs_already_is_shown_then_kept_under_the_change(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        by_hand = here.original.replace("timeout: 0.5", "timeout: 0.6")
        here.path.write_text(by_hand, encoding="utf-8")
        here.bridge.hangup()  # SIGHUP before any page change: the bridge runs the file
        await eventually(lambda: here.bridge.loaded.config.buses[0].timeout == 0.6)

        shown = await here.edit("pump", {"name": "Well pump"})  # the page says so, once

        assert shown.status == 409, shown.body
        assert "+    timeout: 0.6" in shown.json()["diff"]
        answer = await here.edit("pump", {"name": "Well pump"})
        assert answer.status == 200, answer.body
        assert answer.json()["changes"] == {"restarted": ["pump"]}
        expected = by_hand.replace("name: Borehole pump   #", "name: Well pump       #")
        assert here.path.read_text(encoding="utf-8") == expected
