"""``mapping: sunspec`` devices end to end: the real engine and management (the walks run
beside the polls, bridge/sunspec_devices.py) against SunSpec images served by the
simulator over loopback TCP and RTU on a pty pair, next to a seed device.

The values published are pysunspec2's of the same registers (tests/sunspec_reference.py);
the built mapping is cached in the state folder and a restart polls with it before any
walk; a changed chain (another image at the unit) is rebuilt; a silent SunSpec unit and a
unit that is not SunSpec are offline with the reason and never delay the seed's polls.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from bridge import sunspec_devices
from bridge.app import Bridge
from bridge.config import LoadedConfig, load_config_data
from bridge.core.counters import counters_of
from bridge.core.health import Fault
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.errors import DeviceExceptionError
from bridge.management import Management
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator, SunSpecUnit
from bridge.sunspec.image import DeviceImage, build_image
from bridge.sunspec.mapping import build_from_device
from tests.integration.harness import (
    FAST_POLICY,
    Recorder,
    cancel,
    eventually,
    serving_serial,
    serving_tcp,
    tcp_bus,
)
from tests.integration.mosquitto import Broker
from tests.integration.test_management import client_of, request
from tests.sunspec_devices import every_image
from tests.sunspec_reference import differences, expected_values, reference_models

IMAGES = every_image()
BAUD = 115200
POLL = {"fast": 0.2, "slow": 0.5}


def image(name: str, base: int) -> DeviceImage:
    return build_image(IMAGES[name], base, name)


async def built_of(served: DeviceImage) -> Any:
    """The mapping built from ``served``'s registers, in memory."""
    registers = served.registers

    async def read(address: int, count: int) -> list[int]:
        if not all(a in registers for a in range(address, address + count)):
            raise DeviceExceptionError(2, "illegal data address", "fail")
        return [registers[a] for a in range(address, address + count)]

    return await build_from_device(read)


async def expected(served: DeviceImage) -> dict[str, Any]:
    """pysunspec2's value of every entity the bridge builds for ``served``."""
    chain, built = await built_of(served)
    return expected_values(built, reference_models(served, chain, IMAGES[served.name]))


def site_config(folder: Path, buses: list[dict[str, Any]], devices: list[dict[str, Any]]) -> Any:
    data = {"bridge": {"state_dir": "state"}, "buses": buses, "devices": devices}
    return load_config_data(data, folder / "config.yaml")


@contextlib.asynccontextmanager
async def running(
    loaded: LoadedConfig, engine: Engine | None = None
) -> AsyncIterator[tuple[Engine, Management, Recorder]]:
    """The engine with its management (which adds the SunSpec walks to the engine)."""
    recorder = Recorder()
    engine = engine or Engine(loaded, recorder, policy=FAST_POLICY)
    reloaded: list[list[str]] = []

    async def on_reload(ids: list[str]) -> None:
        reloaded.append(ids)

    management = Management(loaded, engine, on_reload=on_reload, mqtt_state=lambda: "online")
    task = asyncio.create_task(engine.run())
    try:
        yield engine, management, recorder
    finally:
        await cancel(task)


def all_read(engine: Engine, device_id: str, wanted: dict[str, Any]) -> bool:
    values = engine.devices[device_id].values
    return all(key in values for key, value in wanted.items() if value is not None)


def seed_unit(unit: int) -> SimulatedUnit:
    return SimulatedUnit(unit, load_mapping(builtin_mapping_path("soft_starter")))


SEED = {"id": "starter", "bus": "tcp", "unit": 1, "mapping": "soft_starter", "poll": POLL}


@pytest.mark.asyncio
async def test_tcp_and_rtu_devices_built_published_as_pysunspec2_and_cached(
    tmp_path: Path,
) -> None:
    tcp_image, rtu_image = image("inverter_mppt", 40000), image("meter", 50000)
    want = {"inverter": await expected(tcp_image), "meter": await expected(rtu_image)}
    tcp_sim = Simulator([seed_unit(1), SunSpecUnit(2, tcp_image)], tick=0)
    rtu_sim = Simulator([SunSpecUnit(3, rtu_image)], tick=0)
    async with (
        serving_tcp(tcp_sim) as port,
        serving_serial(rtu_sim, baudrate=BAUD) as line,
    ):
        rtu = {"id": "rs485", "transport": "rtu", "port": line, "baudrate": BAUD, "timeout": 1.0}
        loaded = site_config(
            tmp_path,
            [tcp_bus(port, timeout=1.0), rtu],
            [
                SEED,
                {"id": "inverter", "bus": "tcp", "unit": 2, "mapping": "sunspec", "poll": POLL},
                {
                    "id": "meter",
                    "bus": "rs485",
                    "unit": 3,
                    "mapping": "sunspec",
                    "sunspec": {"base": 50000},
                    "poll": POLL,
                },
            ],
        )
        assert not loaded.mappings["inverter"].entities  # nothing cached yet: pending
        async with running(loaded) as (engine, _, recorder):
            await eventually(lambda: all(all_read(engine, d, w) for d, w in want.items()), 30)
            assert engine.devices["starter"].health.online
            for device_id, wanted in want.items():
                assert differences(engine.devices[device_id].values, wanted) == [], device_id
                published = {k for u in recorder.of(device_id) for k in u.changed}
                assert {k for k, v in wanted.items() if v is not None} <= published
    assert not tcp_sim.writes
    assert not rtu_sim.writes
    for device_id in want:
        cached = tmp_path / "state" / "sunspec"
        assert load_mapping(cached / f"{device_id}.yaml") == loaded.mappings[device_id]
        record = json.loads((cached / f"{device_id}.json").read_text())
        assert record["signature"]["base"] == (40000 if device_id == "inverter" else 50000)


async def _run_once(tmp_path: Path, served: DeviceImage) -> tuple[Simulator, LoadedConfig, Any]:
    """One run of a config with the seed and one SunSpec device at unit 2, until the
    SunSpec device's walks are done and its values read."""
    sim = Simulator([seed_unit(1), SunSpecUnit(2, served)], tick=0)
    want = await expected(served)
    async with serving_tcp(sim) as port:
        inverter = {"id": "inverter", "bus": "tcp", "unit": 2, "mapping": "sunspec", "poll": POLL}
        loaded = site_config(tmp_path, [tcp_bus(port, timeout=1.0)], [SEED, inverter])
        async with running(loaded) as (engine, management, _):
            await eventually(lambda: management.sunspec.walks >= 1, 20)
            await eventually(lambda: all_read(engine, "inverter", want), 20)
            await eventually(lambda: engine.devices["inverter"].mapping.entities, 20)
            assert differences(engine.devices["inverter"].values, want) == []
    assert not sim.writes
    return sim, loaded, management


@pytest.mark.asyncio
async def test_a_restart_polls_with_the_cached_mapping_before_any_walk(tmp_path: Path) -> None:
    served = image("inverter_123", 40000)
    _, first, _ = await _run_once(tmp_path, served)
    sim, again, management = await _run_once(tmp_path, served)
    assert again.mappings["inverter"] == first.mappings["inverter"]  # loaded from the cache
    asked = [address for unit, _, address in sim.requests if unit == 2]
    marker = asked.index(40000)  # the check's walk: the marker read
    assert marker > 0, "a poll came first"
    assert all(a != 40000 for a in asked[:marker])
    assert management.sunspec.walks == 1  # the check only: the chain is the same


@pytest.mark.asyncio
async def test_a_changed_chain_is_rebuilt_and_cached_again(tmp_path: Path) -> None:
    _, first, _ = await _run_once(tmp_path, image("inverter_123", 40000))
    signature = json.loads((tmp_path / "state/sunspec/inverter.json").read_text())["signature"]
    _, again, management = await _run_once(tmp_path, image("inverter_mppt", 40000))
    assert management.sunspec.walks == 2  # the check, then the build
    assert again.mappings["inverter"] != first.mappings["inverter"]
    record = json.loads((tmp_path / "state/sunspec/inverter.json").read_text())
    assert record["signature"] != signature
    assert load_mapping(tmp_path / "state/sunspec/inverter.yaml") == again.mappings["inverter"]


@pytest.mark.asyncio
async def test_a_firmware_update_while_running_is_found_when_the_device_answers_again(
    tmp_path: Path,
) -> None:
    """A firmware update reboots the device: silent a while, then another model chain.
    When it answers again its chain is walked again and the new mapping built, swapped
    in and cached, with no request from anyone; its values are pysunspec2's again."""
    first, updated = image("inverter_123", 40000), image("inverter_mppt", 40000)
    sim = Simulator([seed_unit(1), SunSpecUnit(2, first)], tick=0)
    want = await expected(updated)
    async with serving_tcp(sim) as port:
        inverter = {"id": "inverter", "bus": "tcp", "unit": 2, "mapping": "sunspec", "poll": POLL}
        loaded = site_config(tmp_path, [tcp_bus(port, timeout=0.3)], [SEED, inverter])
        async with running(loaded) as (engine, management, _):
            await eventually(lambda: engine.devices["inverter"].health.online is True, 20)
            before = engine.devices["inverter"].mapping
            walks = management.sunspec.walks
            sim.set_quirks(2, Quirks(dead=True))  # rebooting
            await eventually(lambda: engine.devices["inverter"].health.online is False, 20)
            sim.swap_image(2, updated)
            sim.set_quirks(2, Quirks())  # up again, with the new firmware
            await eventually(lambda: engine.devices["inverter"].mapping != before, 20)
            await eventually(lambda: all_read(engine, "inverter", want), 20)
            assert differences(engine.devices["inverter"].values, want) == []
            assert management.sunspec.walks > walks
            assert engine.devices["starter"].health.online is True
    cached = load_mapping(tmp_path / "state/sunspec/inverter.yaml")
    assert cached == engine.devices["inverter"].mapping


@pytest.mark.asyncio
async def test_a_device_that_keeps_dropping_off_is_checked_once_per_gap(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A noisy line drops the inverter off and on again and again: its chain is checked
    at its first return, and not again within ``REWALK_GAP`` (10 min by default; an hour
    here), however often it returns."""
    monkeypatch.setattr(sunspec_devices, "REWALK_GAP", 3600.0)
    sim = Simulator([seed_unit(1), SunSpecUnit(2, image("inverter_123", 40000))], tick=0)
    async with serving_tcp(sim) as port:
        inverter = {"id": "inverter", "bus": "tcp", "unit": 2, "mapping": "sunspec", "poll": POLL}
        loaded = site_config(tmp_path, [tcp_bus(port, timeout=0.3)], [SEED, inverter])
        async with running(loaded) as (engine, management, _):
            await eventually(lambda: engine.devices["inverter"].health.online is True, 20)
            await eventually(lambda: management.sunspec.walks >= 1, 20)  # built at the start
            walks = management.sunspec.walks
            for returned in range(3):
                sim.set_quirks(2, Quirks(dead=True))
                await eventually(lambda: engine.devices["inverter"].health.online is False, 20)
                await asyncio.sleep(2 * sunspec_devices.WATCH)  # the watcher saw it offline
                sim.set_quirks(2, Quirks())
                await eventually(lambda: engine.devices["inverter"].health.online is True, 20)
                if returned == 0:
                    await eventually(lambda: management.sunspec.walks == walks + 1, 20)
            await asyncio.sleep(3 * sunspec_devices.WATCH)  # the watcher looked again
            assert management.sunspec.walks == walks + 1


@pytest.mark.asyncio
async def test_a_dead_and_a_non_sunspec_unit_are_offline_and_delay_no_other(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """The dead unit is walked again every 0.2-0.4 s here (5 s to 5 min by default),
    each walk one timeout at poll priority; the unit without a marker once (10 min)."""
    monkeypatch.setattr(sunspec_devices, "BACKOFF_INITIAL", 0.2)
    monkeypatch.setattr(sunspec_devices, "BACKOFF_MAX", 0.4)
    sim = Simulator([seed_unit(1), seed_unit(4)], tick=0, read_log=1000)
    async with serving_tcp(sim) as port:
        devices = [
            SEED,
            {"id": "dead", "bus": "tcp", "unit": 9, "mapping": "sunspec"},  # nobody answers
            {"id": "other", "bus": "tcp", "unit": 4, "mapping": "sunspec"},  # no marker
        ]
        loaded = site_config(tmp_path, [tcp_bus(port, timeout=0.3)], devices)
        async with running(loaded) as (engine, _, _):
            await eventually(lambda: engine.devices["starter"].first_poll_done, 10)
            start = time.monotonic()
            await eventually(lambda: engine.devices["dead"].health.online is False, 10)
            await eventually(lambda: engine.devices["other"].health.online is False, 10)
            await asyncio.sleep(max(0.0, start + 3.0 - time.monotonic()))
            dead, other = engine.devices["dead"].health, engine.devices["other"].health
            assert dead.fault is Fault.UNMAPPED
            assert "SunSpec walk failed" in dead.lock_reason
            assert other.fault is Fault.UNMAPPED
            assert "not a SunSpec device" in other.lock_reason
            assert engine.devices["starter"].health.online
            reported = {d.device_id: d.error for d in engine.snapshot().devices}
            assert reported["other"] == other.lock_reason
            assert reported["starter"] is None
    times = [t for _, t in sim.reads(1) if t >= start]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    # fast polls every 0.2 s; a walk of the dead unit costs at most one timeout (0.3 s)
    assert gaps and max(gaps) < 0.2 + 0.3 + 0.5, max(gaps)
    assert caplog.text.count("dead: SunSpec walk failed") >= 4
    assert caplog.text.count("other: not a SunSpec device") == 1
    assert [a for unit, _, a in sim.requests if unit == 4].count(40000) == 1
    assert not tmp_path.joinpath("state/sunspec/dead.json").exists()
    assert not sim.writes


@pytest.mark.asyncio
async def test_over_mqtt_discovered_offline_and_rewalked_on_request(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """The built entities are discovered, a dead SunSpec unit is published offline, a
    rewalk request rebuilds a changed chain (discovery again) and a retained one is
    refused without a walk."""
    sim = Simulator([seed_unit(1), SunSpecUnit(2, image("inverter_123", 40000))], tick=0)
    async with serving_tcp(sim) as port:
        data = {
            "mqtt": {"url": mosquitto.url},
            "buses": [tcp_bus(port, timeout=0.5)],
            "devices": [
                SEED,
                {"id": "inverter", "bus": "tcp", "unit": 2, "mapping": "sunspec", "poll": POLL},
                {"id": "dead", "bus": "tcp", "unit": 9, "mapping": "sunspec"},
            ],
        }
        bridge = Bridge(load_config_data(data, tmp_path / "config.yaml"))
        task = asyncio.create_task(bridge.run())
        try:
            async with client_of(mosquitto) as tester:
                await tester.client.subscribe("modbus/+/availability", "modbus/inverter")
                await _published_as_pysunspec2(tester, image("inverter_123", 40000))
                await _rewalks(bridge, sim, tester, tmp_path)
        finally:
            await cancel(task)
    assert not sim.writes


async def _published_as_pysunspec2(tester: Any, served: DeviceImage) -> None:
    """The device's JSON on the broker holds pysunspec2's value of each implemented point."""
    want = {k: v for k, v in (await expected(served)).items() if v is not None}

    def document() -> dict[str, Any]:
        raw = tester.retained.get("modbus/inverter")
        return json.loads(raw) if raw else {}

    await eventually(lambda: all(document().get(k) is not None for k in want), 20)
    shown = document()
    assert differences({k: shown[k] for k in want}, want) == []


async def _rewalks(bridge: Bridge, sim: Simulator, tester: Any, folder: Path) -> None:
    topic = "homeassistant/device/inverter/config"
    await eventually(lambda: topic in tester.retained, 20)
    built = bridge.engine.devices["inverter"].mapping.entities
    assert set(built) <= set(tester.json(topic)["cmps"])
    await eventually(lambda: tester.retained.get("modbus/dead/availability") == b"offline", 20)
    assert "homeassistant/device/dead/config" not in tester.retained
    assert tester.retained.get("modbus/starter/availability") == b"online"

    signature = _signature(folder)
    sim.swap_image(2, image("inverter_mppt", 40000))  # a firmware update
    walks, start = bridge.management.sunspec.walks, len(tester.log)
    request_topic = "modbus/bridge/request/mapping/reload"
    await tester.client.publish(request_topic, b'{"rewalk": true}', retain=True)
    await eventually(lambda: tester.after(start, "modbus/bridge/response/mapping/reload"), 10)
    await tester.client.publish(request_topic, b"", retain=True)  # cleared
    (refused,) = tester.after(start, "modbus/bridge/response/mapping/reload")
    assert json.loads(refused.payload)["status"] == "error"
    assert "retained" in json.loads(refused.payload)["error"]
    assert bridge.management.sunspec.walks == walks
    assert bridge.engine.devices["inverter"].mapping.entities == built

    not_sunspec = await request(tester, "mapping/reload", {"rewalk": True, "devices": ["starter"]})
    assert "not mapping: sunspec devices ['starter']" in not_sunspec["error"]
    before = len(tester.log)
    answer = await request(tester, "mapping/reload", {"rewalk": True, "devices": ["inverter"]})
    assert answer["data"] == {"reloaded": ["inverter"], "changed": ["inverter"], "failed": {}}
    rebuilt = bridge.engine.devices["inverter"].mapping.entities
    assert rebuilt != built
    await eventually(lambda: tester.after(before, topic), 10)
    await eventually(lambda: set(rebuilt) <= set(tester.json(topic)["cmps"]), 10)
    assert _signature(folder) != signature
    assert load_mapping(folder / "state/sunspec/inverter.yaml").entities == rebuilt
    failed = await request(tester, "mapping/reload", {"rewalk": True, "devices": ["dead"]})
    assert set(failed["data"]["failed"]) == {"dead"}


def _signature(folder: Path) -> Any:
    return json.loads((folder / "state/sunspec/inverter.json").read_text())["signature"]


@pytest.mark.asyncio
async def test_a_unit_that_is_not_sunspec_switched_to_its_mapping_file_stays_switched(
    tmp_path: Path,
) -> None:
    sim = Simulator([seed_unit(4)], tick=0)
    async with serving_tcp(sim) as port:
        device = {"id": "other", "bus": "tcp", "unit": 4, "mapping": "sunspec", "poll": POLL}
        data = {
            "bridge": {"mapping_switch": True},
            "buses": [tcp_bus(port, timeout=0.3)],
            "devices": [device],
        }
        loaded = load_config_data(data, tmp_path / "config.yaml")
        async with running(loaded) as (engine, management, _):
            await eventually(lambda: engine.devices["other"].health.online is False, 10)
            assert management.sunspec.ids == ["other"]
            body = {"devices": ["other"], "mapping": "soft_starter"}
            answer = json.loads(
                await management.handle("mapping/reload", json.dumps(body).encode())
            )
            assert answer["data"] == {"reloaded": ["other"], "changed": ["other"]}
            await eventually(lambda: engine.devices["other"].health.online, 10)
            assert management.sunspec.ids == []
            rewalk = await management.handle(
                "mapping/reload", b'{"rewalk": true, "devices": ["other"]}'
            )
            assert "not mapping: sunspec devices ['other']" in json.loads(rewalk)["error"]
            assert engine.devices["other"].mapping == loaded.mappings["other"]
            assert loaded.mappings["other"].model != "device not walked yet"


@pytest.mark.asyncio
async def test_counters_carried_over_before_the_first_build_hold_a_lower_reading(
    tmp_path: Path,
) -> None:
    """The retained document is read before the device has a mapping: its counters wait
    for the built mapping, whose first lower reading is then held, not published."""
    served = image("meter", 40000)
    want = await expected(served)
    points = (await built_of(served))[1].mapping().points().values()
    counters = sorted(k for k in counters_of(points) if isinstance(want.get(k), int | float))
    assert counters, "the image has an energy counter"
    key = counters[0]
    high = want[key] + 1000
    sim = Simulator([SunSpecUnit(2, served)], tick=0)
    async with serving_tcp(sim) as port:
        inverter = {"id": "meter", "bus": "tcp", "unit": 2, "mapping": "sunspec", "poll": POLL}
        loaded = site_config(tmp_path, [tcp_bus(port, timeout=1.0)], [inverter])
        engine = Engine(loaded, Recorder(), policy=FAST_POLICY)
        assert not engine.devices["meter"].points
        engine.devices["meter"].seed_counters({key: high})  # as carry_over does
        async with running(loaded, engine) as (_, _, _):
            await eventually(lambda: all_read(engine, "meter", want), 20)
            await eventually(lambda: engine.devices["meter"].counter_readings_held >= 2, 10)
            assert engine.devices["meter"].values[key] == high


@pytest.mark.asyncio
async def test_a_state_folder_that_cannot_be_written_leaves_the_device_polling(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    served = image("inverter_123", 40000)
    want = await expected(served)
    (tmp_path / "state").write_text("a file where the folder should be", encoding="utf-8")
    sim = Simulator([SunSpecUnit(2, served)], tick=0)
    async with serving_tcp(sim) as port:
        inverter = {"id": "inverter", "bus": "tcp", "unit": 2, "mapping": "sunspec", "poll": POLL}
        loaded = site_config(tmp_path, [tcp_bus(port, timeout=1.0)], [inverter])
        async with running(loaded) as (engine, _, _):
            await eventually(lambda: all_read(engine, "inverter", want), 20)
            assert differences(engine.devices["inverter"].values, want) == []
    assert "inverter: the SunSpec mapping could not be cached" in caplog.text
