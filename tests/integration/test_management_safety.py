"""The management API attacked: mapping switches, guarded and secret registers, input
bounds and busy limits (issue 11 items 6, 7 and 9), over a real Mosquitto and simulator.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
from pathlib import Path
from typing import Any

import pytest

from bridge.config import MqttConfig, load_config_data
from bridge.core.mapping import builtin_mapping_path
from bridge.management import REFUSED_MAPPING, Management
from bridge.modbus.engine import Engine
from bridge.mqtt import MqttClient
from tests.conftest import BROKER_PASSWORD, BROKER_USER
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_management import client_of, online, request, site

FACTORY_RESET = 0x102F  # soft starter: "Restore factory defaults", dangerous in the mapping
SWITCHES = {"mapping_switch": True, "mapping_dirs": ["maps"]}


def harmless_copy(folder: Path) -> Path:
    """The soft starter's mapping with its factory reset declared a harmless button."""
    text = builtin_mapping_path("soft_starter").read_text()
    marked = "    dangerous: true\n    note: Write-only; wipes motor set-up"
    assert marked in text
    (folder / "maps").mkdir(exist_ok=True)
    path = folder / "maps" / "harmless.yaml"
    path.write_text(text.replace(marked, "    note: Write-only; wipes motor set-up"))
    return path


@pytest.mark.asyncio
async def test_mapping_switches_are_off_unless_the_config_turns_them_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    harmless_copy(tmp_path)
    async with site(mosquitto, tmp_path) as (bridge, _), client_of(mosquitto) as tester:
        await online(bridge, tester)
        for mapping in ("maps/harmless.yaml", "p2_vfd"):
            body = {"devices": ["starter"], "mapping": mapping}
            refused = await request(tester, "mapping/reload", body)
            assert refused["status"] == "error"
            assert "bridge.mapping_switch: true" in refused["error"]
        assert bridge.engine.devices["starter"].device.mapping == "soft_starter"
        reloaded = await request(tester, "mapping/reload", {})  # re-reading is always allowed
        assert reloaded["data"] == {"reloaded": ["pump", "starter"], "changed": []}


@pytest.mark.asyncio
async def test_a_refused_mapping_path_reveals_nothing_about_the_file(
    mosquitto: Broker, tmp_path: Path
) -> None:
    harmless_copy(tmp_path)
    outside = tmp_path / "outside.yaml"
    outside.write_text(builtin_mapping_path("soft_starter").read_text())
    (tmp_path / "maps" / "link.yaml").symlink_to(outside)
    (tmp_path / "maps" / "notes.txt").write_text("not a mapping")
    attempts = [
        "outside.yaml",  # exists, beside the config
        "nowhere.yaml",  # does not exist
        str(outside),  # absolute
        "maps/../outside.yaml",
        "maps/link.yaml",  # a link out of the folder
        "maps/notes.txt",
        "/etc/passwd",
        "/etc/nothing/here.yaml",
        "maps/\x00.yaml",
        "../" * 40 + "etc/hostname",
    ]
    async with (
        site(mosquitto, tmp_path, bridge=SWITCHES) as (bridge, _),
        client_of(mosquitto) as tester,
    ):
        await online(bridge, tester)
        for mapping in attempts:
            body = {"devices": ["starter"], "mapping": mapping}
            refused = await request(tester, "mapping/reload", body)
            assert (refused["status"], refused["error"]) == ("error", REFUSED_MAPPING), mapping
        assert bridge.engine.devices["starter"].device.mapping == "soft_starter"
        allowed = {"devices": ["starter"], "mapping": "p2_vfd"}  # a shipped name
        assert (await request(tester, "mapping/reload", allowed))["status"] == "ok"


@pytest.mark.asyncio
async def test_a_switched_mapping_cannot_unguard_a_dangerous_register(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """The harmless copy is accepted (it is under mapping_dirs), but the factory reset it
    declares a plain button stays guarded: not pressed over MQTT, not written raw."""
    harmless_copy(tmp_path)
    async with (
        site(mosquitto, tmp_path, raw_writes=True, bridge=SWITCHES) as (bridge, sim),
        client_of(mosquitto) as tester,
    ):
        await online(bridge, tester)
        body = {"devices": ["starter"], "mapping": "maps/harmless.yaml"}
        switched = await request(tester, "mapping/reload", body)
        assert switched["data"]["changed"] == ["starter"]
        starter = bridge.engine.devices["starter"]
        assert not starter.points["factory_reset"].entity.dangerous  # the file says so
        await online(bridge)

        start = len(tester.log)
        await tester.client.subscribe("modbus/starter/error")
        await tester.client.publish("modbus/starter/factory_reset/set", "PRESS")
        await eventually(lambda: tester.after(start, "modbus/starter/error"), 10)
        error = json.loads(tester.after(start, "modbus/starter/error")[-1].payload)
        assert "guarded" in error["error"] and "allow_dangerous_writes" in error["error"]

        raw = {"device": "starter", "address": FACTORY_RESET, "values": [0]}
        refused = await request(tester, "device/write", raw)
        assert refused["status"] == "error" and "guarded" in refused["error"], refused
        span = {"unit": 3, "address": FACTORY_RESET - 1, "values": [0, 0, 0]}
        refused = await request(tester, "device/write", span)
        assert refused["status"] == "error" and "4143" in refused["error"], refused
        assert not [w for unit, w in sim.writes if unit == 3 and w.address <= FACTORY_RESET]


def first_secret(bridge: Any) -> int:
    """The first wire address of the pump's secret registers."""
    points = bridge.engine.devices["pump"].points.values()
    secret = sorted(a for p in points if p.entity.secret for a in p.span)
    assert secret, "the Nastec mapping marks its password digits secret"
    return secret[0]


@pytest.mark.asyncio
async def test_raw_reads_of_secret_registers_need_allow_raw_writes(
    mosquitto: Broker, tmp_path: Path
) -> None:
    for raw_writes in (False, True):
        async with (
            site(mosquitto, tmp_path, raw_writes=raw_writes) as (bridge, _),
            client_of(mosquitto) as tester,
        ):
            await online(bridge, tester)
            first = first_secret(bridge)
            spans = ({"address": first}, {"address": first - 2, "count": 3})  # one, overlapping
            for target, span in itertools.product(({"device": "pump"}, {"unit": 1}), spans):
                answer = await request(tester, "device/read", target | span)
                if raw_writes:  # read (the overlapping span may cross a gap the pump refuses)
                    assert answer["status"] == "ok" or "count" in span, answer
                    assert "secret" not in (answer["error"] or ""), answer
                else:
                    assert answer["status"] == "error", answer
                    assert "secret or write-only" in answer["error"]
                    assert "allow_raw_writes" in answer["error"]
            points = bridge.engine.devices["pump"].points.values()
            plain = next(p for p in points if p.entity.readable and not p.entity.secret)
            body = {"unit": 1, "table": plain.table.value, "address": plain.address}
            beside = await request(tester, "device/read", body)
            assert beside["status"] == "ok", beside  # registers not secret read as before


@pytest.mark.asyncio
async def test_credentials_in_the_url_log_in_and_show_nowhere(
    mosquitto_auth: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    url = f"mqtt://{BROKER_USER}:{BROKER_PASSWORD}@{mosquitto_auth.host}:{mosquitto_auth.port}"
    caplog.set_level(logging.DEBUG)
    async with site(mosquitto_auth, tmp_path, url=url) as (bridge, _):
        await eventually(lambda: bridge.mqtt_state == "online", 10)  # logged in
        config = MqttConfig(url=mosquitto_auth.url, username=BROKER_USER, password=BROKER_PASSWORD)
        async with MqttClient(config, will_topic="tester/state", client_id="reader") as client:
            found = await client.retained("modbus/bridge/info")
    info = found["modbus/bridge/info"]
    assert BROKER_PASSWORD.encode() not in info
    assert json.loads(info)["config"]["mqtt"]["url"] == mosquitto_auth.url
    assert BROKER_PASSWORD not in caplog.text


@pytest.mark.asyncio
async def test_management_input_is_bounded_before_work(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path) as (bridge, sim), client_of(mosquitto) as tester:
        await online(bridge, tester)
        cases: list[tuple[str, dict[str, Any], str]] = [
            ("device/scan", {"units": "1-100000000"}, "1..247"),
            ("device/scan", {"units": "1-" + "9" * 5000}, "1..247"),
            ("device/scan", {"units": [1, 100000000]}, "1..247"),
            ("device/read", {"unit": 0, "address": 0}, "broadcast"),
            ("device/write", {"unit": 0, "address": 0, "values": [1]}, "broadcast"),
            ("device/scan", {"units": "0-5"}, "1..247"),
        ]
        for command, body, words in cases:
            answer = await request(tester, command, body)
            assert answer["status"] == "error" and words in answer["error"], (body, answer)
        assert not sim.writes


@pytest.mark.asyncio
async def test_one_scan_per_bus_and_few_raw_requests_wait(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as (bridge, _), client_of(mosquitto) as tester:
        await online(bridge, tester)
        first = asyncio.create_task(request(tester, "device/scan", {"units": "4-30"}))
        await eventually(lambda: bridge.management._scanning, 10)
        second = await request(tester, "device/scan", {"units": "1-3"})
        assert second["status"] == "error" and "busy: a scan of bus tcp" in second["error"]
        assert (await first)["status"] == "ok"
        assert (await request(tester, "device/scan", {"units": "1-3"}))["status"] == "ok"

        absent = {"unit": 9, "address": 0, "timeout": 0.5}  # each read waits its timeout
        answers = await asyncio.gather(*(request(tester, "device/read", absent) for _ in range(5)))
        busy = [a for a in answers if a["error"] and a["error"].startswith("busy:")]
        assert len(busy) == 3, answers  # MAX_RAW = 2 wait, the rest are refused at once
        assert all("did not answer" in a["error"] for a in answers if a not in busy), answers


@pytest.mark.asyncio
async def test_serial_units_above_247_are_refused_before_the_bus(tmp_path: Path) -> None:
    data = {
        "buses": [{"id": "rs485", "transport": "rtu", "port": str(tmp_path / "no-port")}],
        "devices": [],
    }
    loaded = load_config_data(data, tmp_path / "config.yaml")
    engine = Engine(loaded)  # not running: nothing may reach its bus

    async def reloaded(_: list[str]) -> None:
        raise AssertionError("nothing to reload")

    management = Management(loaded, engine, on_reload=reloaded, mqtt_state=lambda: "online")
    answer = json.loads(
        await management.handle("device/read", b'{"bus": "rs485", "unit": 250, "address": 0}')
    )
    assert answer["error"] == "unit: serial lines address units 1..247"
    assert engine.schedulers["rs485"].counters.transactions == 0


@pytest.mark.asyncio
async def test_reloading_unchanged_files_restarts_no_device(tmp_path: Path) -> None:
    """A device with protocol overrides in the config keeps its poller (values, learnt
    refusals, health counters) when ``mapping/reload {}`` finds its file unchanged."""
    data = {
        "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": 1}],
        "devices": [
            {"id": "genset", "bus": "tcp", "unit": 5, "mapping": "smartgen_hgm6100"}
            | {"protocol": {"min_request_interval": 0.2, "max_read_registers": 8}},
            {"id": "pump", "bus": "tcp", "unit": 1, "mapping": "nastec_vasco"},
        ],
    }
    loaded = load_config_data(data, tmp_path / "config.yaml")
    engine = Engine(loaded)
    before = dict(engine.devices)

    async def reloaded(changed: list[str]) -> None:
        raise AssertionError(f"nothing changed, yet {changed} were restarted")

    management = Management(loaded, engine, on_reload=reloaded, mqtt_state=lambda: "online")
    answer = json.loads(await management.handle("mapping/reload", b"{}"))
    assert answer["data"] == {"reloaded": ["genset", "pump"], "changed": []}
    assert engine.devices == before  # the same pollers
    assert engine.devices["genset"].protocol.max_read_registers == 8  # overrides still on
