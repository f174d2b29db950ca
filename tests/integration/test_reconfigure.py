"""A new config applied to a running bridge (bridge/reconfigure.py), end to end: a real
Mosquitto, the simulator on loopback. Each change starts, stops or restarts only what it
names; the other devices keep their poller, their counters and their values and miss no
poll (``Untouched``: their polls counted in the simulator's read log across the change).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from pathlib import Path
from typing import Any

import pytest

from bridge.core.entity import PollClass
from bridge.core.gateway import Route
from bridge.core.request import Write
from bridge.errors import BridgeError, ValueRejectedError
from bridge.modbus.simulator import SunSpecUnit
from bridge.sunspec.image import build_image
from tests.integration.harness import eventually, serving_serial, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.reconfigure_site import (
    FAST,
    Site,
    Untouched,
    device,
    published,
    site,
    tcp_bus,
    unit_simulator,
)
from tests.sunspec_devices import every_image

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(120)]
TWO = [device("pump", 1), device("starter", 3)]
BAUD = 57600  # a pty pair carries any rate


def listed(here_retained: dict[str, bytes]) -> list[str]:
    return [d["id"] for d in json.loads(here_retained["modbus/bridge/devices"])]


async def test_a_device_added_is_discovered_and_polled_the_others_poll_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path, TWO) as here:
        untouched = Untouched.of(here, "pump", "starter")
        new = here.changed()
        new["devices"].append(device("drive", 2, name="Main drive"))

        answer = await here.apply(new)

        assert answer == {
            "status": "ok",
            "changes": {"added": ["drive"]},
            "description": "devices added: drive",
        }
        await eventually(lambda: published(here, ["drive"]), timeout=10)
        config = here.observer.json("homeassistant/device/drive/config")
        assert config["device"]["name"] == "Main drive"
        assert here.observer.json("modbus/drive")  # its values
        await eventually(lambda: "drive" in listed(here.observer.retained))
        assert here.bridge.loaded.config.devices[-1].id == "drive"
        await untouched.check()


async def test_a_device_removed_leaves_nothing_retained_the_others_poll_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path, TWO, output="both") as here:
        retained = here.observer.retained
        await eventually(lambda: retained.get("modbus/starter/availability") == b"online")
        assert any(t.startswith("modbus/starter/") and t.count("/") == 2 for t in retained)
        untouched = Untouched.of(here, "pump")
        new = here.changed()
        new["devices"] = [d for d in new["devices"] if d["id"] != "starter"]

        answer = await here.apply(new)

        assert answer["changes"] == {"removed": ["starter"]}
        await eventually(lambda: retained.get("homeassistant/device/starter/config") == b"")
        await eventually(lambda: retained.get("modbus/starter") == b"")
        assert "starter" not in here.bridge.engine.devices
        await eventually(lambda: listed(retained) == ["pump"])
        await untouched.check()
        left = await here.retained_now(
            "modbus/starter", "modbus/starter/#", "homeassistant/device/starter/config"
        )
        assert left == {}
        assert await here.retained_now("homeassistant/device/pump/config")  # still there
        # a command to it now: answered, nothing written
        await here.observer.client.publish("modbus/starter/set", '{"soft_start_time": 20}')
        await eventually(lambda: "modbus/starter/error" in here.observer.retained)
        error = here.observer.json("modbus/starter/error")
        assert error["error"] == "no such device"


async def test_disabled_then_enabled_the_other_polls_on(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path, TWO) as here:
        retained = here.observer.retained
        untouched = Untouched.of(here, "pump")
        off = here.changed()
        off["devices"][1]["enabled"] = False

        assert (await here.apply(off))["changes"] == {"disabled": ["starter"]}
        await eventually(lambda: retained.get("homeassistant/device/starter/config") == b"")
        await eventually(lambda: retained.get("modbus/starter") == b"")
        assert "starter" not in here.bridge.engine.devices
        kept = [d for d in here.bridge.loaded.config.devices if d.id == "starter"]
        assert [d.enabled for d in kept] == [False]  # in the config still
        await untouched.check()

        on = here.changed()
        on["devices"][1]["enabled"] = True
        assert (await here.apply(on))["changes"] == {"enabled": ["starter"]}
        await eventually(lambda: published(here, ["starter"]), timeout=10)
        await untouched.check()


async def test_renamed_its_discovery_follows_the_other_polls_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path, TWO) as here:
        untouched = Untouched.of(here, "pump")
        new = here.changed()
        new["devices"][1]["name"] = "Well starter"

        assert (await here.apply(new))["changes"] == {"restarted": ["starter"]}

        def named() -> str:
            return here.observer.json("homeassistant/device/starter/config")["device"]["name"]

        await eventually(lambda: named() == "Well starter", timeout=10)
        await untouched.check()


async def test_moved_to_another_unit_it_polls_there_the_other_polls_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path, TWO) as here:
        untouched = Untouched.of(here, "starter")
        new = here.changed()
        new["devices"][0]["unit"] = 4
        before = len(here.sim.reads(4))

        assert (await here.apply(new))["changes"] == {"restarted": ["pump"]}

        assert here.bridge.engine.devices["pump"].device.unit == 4
        await eventually(lambda: len(here.sim.reads(4)) > before + 3)
        await untouched.check()


async def test_a_poll_interval_changed_the_other_polls_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path, TWO) as here:
        untouched = Untouched.of(here, "pump")
        new = here.changed()
        new["devices"][1]["poll"] = {"fast": 2 * FAST, "slow": 5}

        assert (await here.apply(new))["changes"] == {"restarted": ["starter"]}

        assert here.bridge.engine.devices["starter"].intervals[PollClass.FAST] == 2 * FAST
        await untouched.check()


async def test_a_bus_added_changed_and_removed_the_first_bus_polls_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with contextlib.AsyncExitStack() as stack:
        here = await stack.enter_async_context(site(mosquitto, tmp_path, TWO))
        port = await stack.enter_async_context(serving_tcp(unit_simulator()))
        untouched = Untouched.of(here, "pump", "starter")
        added = here.changed()
        added["buses"].append(tcp_bus("lan", port))
        added["devices"].append(device("drive", 2, bus="lan"))

        answer = await here.apply(added)

        assert answer["changes"] == {"buses_added": ["lan"], "added": ["drive"]}
        await eventually(lambda: published(here, ["drive"]), timeout=10)
        assert here.bridge.engine.devices["drive"].scheduler.bus_id == "lan"
        await untouched.check()

        drive = here.bridge.engine.devices["drive"]
        changed = here.changed()
        changed["buses"][1]["timeout"] = 0.8
        answer = await here.apply(changed)
        assert answer["changes"] == {"buses_restarted": ["lan"], "restarted": ["drive"]}
        restarted = here.bridge.engine.devices["drive"]
        assert restarted is not drive
        assert restarted.scheduler.transport.bus.timeout == 0.8
        await eventually(lambda: restarted.health.online is True)
        await untouched.check()

        removed = here.changed()
        removed["buses"].pop()
        removed["devices"].pop()
        answer = await here.apply(removed)
        assert answer["changes"] == {"buses_removed": ["lan"], "removed": ["drive"]}
        assert sorted(here.bridge.engine.schedulers) == ["tcp"]
        await eventually(lambda: here.observer.retained.get("modbus/drive") == b"")
        await untouched.check()


@pytest.mark.parametrize(
    ("section", "change", "named"),
    [
        ("mqtt", {"base_topic": "site"}, "mqtt.base_topic"),
        ("bridge", {"web": {"enabled": True, "token": "x" * 32}}, "bridge.web"),
        (
            "bridge",
            {"gateway": {"enabled": True, "port": 0, "units": {1: "pump"}}},
            "bridge.gateway",
        ),
    ],
)
async def test_a_change_that_needs_a_restart_is_refused_whole(
    mosquitto: Broker, tmp_path: Path, section: str, change: dict[str, object], named: str
) -> None:
    async with site(mosquitto, tmp_path, TWO) as here:
        untouched = Untouched.of(here, "pump", "starter")
        before = here.bridge.loaded
        new = here.changed()
        new[section] = new[section] | change
        new["devices"].append(device("drive", 2))  # would be applied alone: not with it
        new["devices"][0]["name"] = "Renamed"

        answer = await here.apply(new)

        assert answer["status"] == "refused"
        assert answer["restart"] == [named]
        assert named in answer["error"]
        assert here.bridge.loaded is before
        assert sorted(here.bridge.engine.devices) == ["pump", "starter"]
        await untouched.check()


async def test_sighup_applies_the_file_and_a_bad_file_changes_nothing(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge")
    async with site(mosquitto, tmp_path, TWO) as here:
        untouched = Untouched.of(here, "pump", "starter")
        new = here.changed()
        new["devices"].append(device("drive", 2))
        here.path.write_text(json.dumps(new), encoding="utf-8")  # JSON is YAML

        here.bridge.hangup()

        await eventually(lambda: published(here, ["drive"]), timeout=10)
        await eventually(lambda: "SIGHUP: mappings changed" in caplog.text)
        assert "SIGHUP: config changes: devices added: drive" in caplog.text
        loaded = here.bridge.loaded

        here.path.write_text("devices: [\n", encoding="utf-8")
        caplog.clear()
        here.bridge.hangup()
        await eventually(lambda: "SIGHUP: mappings changed" in caplog.text)
        assert "SIGHUP: the config file is not applied, nothing changed" in caplog.text
        assert here.bridge.loaded is loaded
        assert sorted(here.bridge.engine.devices) == ["drive", "pump", "starter"]
        await untouched.check()


async def test_nothing_changed_is_applied_as_nothing(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path, TWO) as here:
        untouched = Untouched.of(here, "pump", "starter")
        answer = await here.apply(here.changed())
        assert answer == {"status": "ok", "changes": {}, "description": "nothing"}
        await asyncio.sleep(0)
        await untouched.check()


async def between_two_commands(
    here: Site, change: dict[str, Any]
) -> tuple[dict[str, Any], asyncio.Task[Any], list[Write]]:
    """The starter's first command (two registers) written while ``change`` is applied: the
    change begins at the command's first frame and a second command is sent right after it
    (it comes after the change). Answers the change's answer, the second command's task
    and the frames written to the starter from the first command on."""
    dispatcher = here.bridge.dispatcher
    values = here.bridge.engine.devices["starter"].values
    items = {key: 20.0 if values[key] != 20.0 else 21.0 for key in FIRST_KEYS}
    then = {SECOND_KEY: 5.0 if values[SECOND_KEY] != 5.0 else 6.0}
    loaded = await here.load(change)
    deadline = time.monotonic() + 10
    writes = len(here.sim.writes)
    started: list[asyncio.Task[Any]] = []
    midway: list[bool] = []  # the first command had ended when its first frame came

    def on_write(unit: int, write: Write) -> dict[Any, int]:
        del write
        if unit == 3 and not started:
            midway.append(first.done())
            started.append(asyncio.create_task(here.bridge.apply_config(loaded)))
            started.append(asyncio.create_task(dispatcher.write_for("starter", then, deadline)))
        return {}

    here.sim.reactions.append(on_write)
    first = asyncio.create_task(dispatcher.write_for("starter", items, deadline))
    await eventually(lambda: bool(started))
    applying, second = started
    assert midway == [False]  # the change began in the middle of the first command
    assert await first == items  # ended whole
    answer = await applying
    with contextlib.suppress(BridgeError):
        await second
    return answer, second, [w for unit, w in here.sim.writes[writes:] if unit == 3]


FIRST_KEYS = ("soft_start_time", "soft_stop_time")
SECOND_KEY = "kick_start_time"


async def test_a_device_removed_between_two_of_its_commands(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """The command running (two registers) ends whole before the device stops; the one
    after it is answered that the device is gone, and nothing of it is written."""
    async with site(mosquitto, tmp_path, TWO) as here:
        new = here.changed()
        new["devices"].pop()

        answer, second, written = await between_two_commands(here, new)

        assert answer["changes"] == {"removed": ["starter"]}
        with pytest.raises(ValueRejectedError, match="no device 'starter'"):
            second.result()
        assert len(written) == 2  # both of the first, nothing of the second


async def test_a_bus_restarted_between_two_commands(mosquitto: Broker, tmp_path: Path) -> None:
    """The command running (two registers) ends whole before its bus restarts (the old
    port closed under it would cut it in half); the one after it runs on the new one."""
    async with site(mosquitto, tmp_path, TWO) as here:
        new = here.changed()
        new["buses"][0]["timeout"] = 0.6

        answer, second, written = await between_two_commands(here, new)

        assert answer["changes"] == {"buses_restarted": ["tcp"], "restarted": ["pump", "starter"]}
        assert second.result()
        assert len(written) == 3
        assert here.bridge.engine.devices["starter"].scheduler.transport.bus.timeout == 0.6


FACTORY_RESET = 0x102F  # the soft starter's, dangerous in its mapping


async def raw_reset(here: Site, **target: Any) -> dict[str, Any]:
    """A raw write of the starter's factory reset register, as the management API takes it
    (to the device, or to ``target``: a bus and unit)."""
    target = target or {"device": "starter"}
    payload = json.dumps(target | {"address": FACTORY_RESET, "values": [0]})
    answer: dict[str, Any] = json.loads(
        await here.bridge.management.handle("device/write", payload.encode())
    )
    return answer


async def test_dangerous_registers_stay_guarded_whatever_the_new_config_says(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """``allow_dangerous_writes`` is the only switch: on, the write goes; off again, it is
    refused; and a mapping that does not mark the register keeps it guarded, polled or
    disabled."""
    async with site(mosquitto, tmp_path, TWO) as here:
        refused = await raw_reset(here)
        assert refused["status"] == "error"
        assert "dangerous" in refused["error"], refused

        allowed = here.changed()
        allowed["devices"][1]["allow_dangerous_writes"] = True
        assert (await here.apply(allowed))["changes"] == {"restarted": ["starter"]}
        assert (await raw_reset(here))["status"] == "ok"

        other = here.changed()
        other["devices"][1] |= {"allow_dangerous_writes": False, "mapping": "vacon_nx"}
        assert (await here.apply(other))["changes"] == {"restarted": ["starter"]}
        assert await raw_reset(here) == refused  # vacon_nx's own guard has no 0x102F

        disabled = here.changed()
        disabled["devices"][1]["enabled"] = False
        assert (await here.apply(disabled))["changes"] == {"disabled": ["starter"]}
        answer = await raw_reset(here, bus="tcp", unit=3)  # not polled: still guarded
        assert answer["status"] == "error"
        assert "dangerous" in answer["error"], answer


async def test_a_sunspec_device_added_is_walked_and_published_then_removed(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """Its walks start with it (bridge/sunspec_devices.py), and stop before it does."""
    served = build_image(every_image()["inverter_mppt"], 40000, "inverter_mppt")
    async with site(mosquitto, tmp_path, TWO, extra=(SunSpecUnit(5, served),)) as here:
        untouched = Untouched.of(here, "pump", "starter")
        added = here.changed()
        sunspec = {"id": "inverter", "bus": "tcp", "unit": 5, "mapping": "sunspec"}
        added["devices"].append(sunspec | {"poll": {"fast": FAST, "slow": 5}})

        assert (await here.apply(added))["changes"] == {"added": ["inverter"]}

        await eventually(lambda: published(here, ["inverter"]), timeout=30)
        assert here.bridge.engine.devices["inverter"].mapping.entities  # built
        await untouched.check()

        removed = here.changed()
        removed["devices"].pop()
        assert (await here.apply(removed))["changes"] == {"removed": ["inverter"]}
        retained = here.observer.retained
        await eventually(lambda: retained.get("homeassistant/device/inverter/config") == b"")
        assert here.bridge.management.sunspec.ids == []
        await untouched.check()  # the walks ended with it: nothing failed


async def test_the_gateway_routes_a_unit_to_a_device_added_live(
    mosquitto: Broker, tmp_path: Path
) -> None:
    gateway = {"enabled": True, "port": 0, "units": {10: {"bus": "tcp", "unit": 4}}}
    async with site(mosquitto, tmp_path, TWO, bridge_section={"gateway": gateway}) as here:
        assert here.bridge.gateway is not None
        assert here.bridge.gateway.routes[10] == Route("tcp", 4, None)
        new = here.changed()
        new["devices"].append(device("well", 4))

        assert (await here.apply(new))["changes"] == {"added": ["well"]}

        assert here.bridge.gateway.routes[10] == Route("tcp", 4, "well")
        assert here.bridge.gateway.loaded is here.bridge.loaded


async def test_a_serial_bus_changed_reopens_its_port_the_other_bus_polls_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """A serial line's new baud rate: its port closed, then opened again with it (a serial
    port is opened once at a time), its device polled again; the TCP bus untouched."""
    async with contextlib.AsyncExitStack() as stack:
        here = await stack.enter_async_context(site(mosquitto, tmp_path, TWO))
        line = await stack.enter_async_context(serving_serial(unit_simulator(), baudrate=BAUD))
        rtu = {"id": "rs485", "transport": "rtu", "port": line, "baudrate": BAUD, "timeout": 1}
        added = here.changed()
        added["buses"].append(rtu)
        added["devices"].append(device("drive", 2, bus="rs485"))
        assert (await here.apply(added))["changes"] == {
            "buses_added": ["rs485"],
            "added": ["drive"],
        }
        await eventually(lambda: published(here, ["drive"]), timeout=15)
        untouched = Untouched.of(here, "pump", "starter")
        before = here.bridge.engine.schedulers["rs485"]

        faster = here.changed()
        faster["buses"][1]["baudrate"] = 2 * BAUD
        answer = await here.apply(faster)

        assert answer["changes"] == {"buses_restarted": ["rs485"], "restarted": ["drive"]}
        assert not before.transport.connected  # the old port closed
        drive = here.bridge.engine.devices["drive"]
        assert drive.scheduler is here.bridge.engine.schedulers["rs485"] is not before
        assert drive.scheduler.transport.bus.baudrate == 2 * BAUD
        requests = drive.health.requests
        await eventually(lambda: drive.health.requests > requests + 2 and drive.health.online)
        await untouched.check()
