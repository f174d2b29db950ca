"""Many entities on one register, end to end: a real Mosquitto, the simulator over TCP and
`Bridge.run()`; and the gateway, another master writing the same registers. A hybrid inverter's work mode is a raw word, a select, a switch with its
words and a read-only view on one holding register; its breaker word is a dangerous
switch's, shared by a harmless raw number and a harmless reset button."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest
import yaml

from bridge.app import Bridge
from bridge.config import load_config_data
from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.core.request import Write
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.integration.harness import cancel, eventually, serving_tcp
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing
from tests.integration.test_gateway_server import gateway_for, master

pytestmark = pytest.mark.asyncio
H = Table.HOLDING
UNIT = 1
MODE, BREAKER = 0x3000, 0x3100
MAPPING = {
    "manufacturer": "Example",
    "model": "Hybrid inverter",
    "description": "a work mode register with four views, a guarded breaker word",
    "source": {"title": "written for tests/integration/test_shared_register.py"},
    "entities": {
        "work_mode_raw": {"name": "Work mode raw", "address": MODE, "access": "rw"},
        "work_mode": {
            "name": "Work mode",
            "address": MODE,
            "access": "rw",
            "enum": {0: "self_use", 1: "backup", 2: "feed_in"},
        },
        "backup": {
            "name": "Backup",
            "address": MODE,
            "type": "bool",
            "access": "rw",
            "words": {"write_on": 1, "write_off": 0, "read_off": [0, 2]},
        },
        "feeding_in": {"name": "Feeding in", "address": MODE, "on_when": {"min": 2, "max": 2}},
        "breaker": {
            "name": "Breaker",
            "address": BREAKER,
            "type": "bool",
            "access": "rw",
            "dangerous": True,
            "words": {"write_on": 0x0100, "write_off": 0x0200},
        },
        "breaker_raw": {"name": "Breaker raw", "address": BREAKER, "access": "rw"},
        "reset_trip": {"name": "Reset trip", "address": BREAKER, "access": "w", "press": 0x0300},
    },
}
VIEWS = ("work_mode_raw", "work_mode", "backup", "feeding_in")


def bridge_of(broker: Broker, port: int, folder: Path) -> Bridge:
    """The bridge, its config and the mapping (``inverter.yaml``) in ``folder``."""
    data = {
        "mqtt": {"url": broker.url, "base_topic": "modbus", "command_expiry": 3},
        "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}],
        "devices": [
            {
                "id": "inverter",
                "bus": "tcp",
                "unit": UNIT,
                "mapping": "inverter.yaml",
                "poll": {"fast": 0.5, "slow": 5},
            }
        ],
    }
    return Bridge(load_config_data(data, folder / "config.yaml"))


def documents(observer: Observer, since: int) -> list[dict[str, object]]:
    return [json.loads(m.payload) for m in observer.after(since, "modbus/inverter")]


async def test_a_switch_a_select_and_a_raw_word_on_one_register(
    mosquitto: Broker, tmp_path: Path
) -> None:
    path = tmp_path / "inverter.yaml"
    path.write_text(yaml.safe_dump(MAPPING), encoding="utf-8")
    sim = Simulator([SimulatedUnit(UNIT, load_mapping(path))])
    sim.set_value(UNIT, "work_mode", "self_use")
    sim.set_value(UNIT, "breaker_raw", 0x0200)
    async with (
        observing(mosquitto, "modbus/#") as observer,
        serving_tcp(sim) as port,
    ):
        task = asyncio.create_task(bridge_of(mosquitto, port, tmp_path).run())
        try:
            await eventually(
                lambda: (
                    "modbus/inverter" in observer.retained
                    and observer.json("modbus/inverter").get("work_mode") == "self_use"
                ),
                timeout=15,
            )
            publish = observer.client.publish
            # the switch: its word written once, every view published from one read back
            since, written = len(observer.log), len(sim.writes)
            await publish("modbus/inverter/backup/set", "ON")
            await eventually(lambda: observer.json("modbus/inverter").get("backup") is True, 10)
            assert sim.writes[written:] == [(UNIT, Write(6, H, MODE, (1,)))]
            assert sim.value(UNIT, "work_mode_raw") == 1
            first = next(d for d in documents(observer, since) if d.get("backup") is True)
            assert {k: first[k] for k in VIEWS} == {
                "work_mode_raw": 1,
                "work_mode": "backup",
                "backup": True,
                "feeding_in": False,
            }
            # the select: the switch reads off, the view on, the raw number 2
            await publish("modbus/inverter/set", json.dumps({"work_mode": "feed_in"}))
            await eventually(lambda: observer.json("modbus/inverter").get("feeding_in") is True)
            state = observer.json("modbus/inverter")
            assert (state["work_mode_raw"], state["backup"]) == (2, False)
            assert sim.value(UNIT, "work_mode_raw") == 2
            # a command asking the register for two words: refused whole, nothing written
            errors, written = len(observer.log), len(sim.writes)
            contradictory = json.dumps({"backup": "ON", "work_mode_raw": 0})
            await publish("modbus/inverter/set", contradictory)
            await eventually(lambda: len(observer.after(errors, "modbus/inverter/error")) == 2)
            refused = {
                e["key"]: e["error"]
                for e in (
                    json.loads(m.payload) for m in observer.after(errors, "modbus/inverter/error")
                )
            }
            assert "another value than backup" in refused["work_mode_raw"]
            assert "not written" in refused["backup"]
            # the breaker word: the harmless raw number writes no breaker word, the reset
            # button's word passes
            for word in (0x0100, 0x0400):
                await publish("modbus/inverter/breaker_raw/set", str(word))
            await eventually(lambda: len(observer.after(errors, "modbus/inverter/error")) == 4)
            guarded = [
                json.loads(m.payload) for m in observer.after(errors, "modbus/inverter/error")
            ]
            assert all("guarded write" in e["error"] for e in guarded[2:])
            await asyncio.sleep(0.3)
            assert sim.writes[written:] == []
            assert sim.value(UNIT, "breaker_raw") == 0x0200
            await publish("modbus/inverter/breaker_raw/set", str(0x0300))
            await eventually(lambda: observer.json("modbus/inverter").get("breaker_raw") == 0x0300)
            assert sim.writes[written:] == [(UNIT, Write(6, H, BREAKER, (0x0300,)))]
        finally:
            await cancel(task)


async def test_a_gateway_master_writes_a_shared_register_as_a_command_of_its_entities(
    tmp_path: Path,
) -> None:
    """Another master's words to the work-mode register become a command of the entities
    that take them (one frame on the line); to the breaker word, only the harmless reset
    word passes the guard."""
    path = tmp_path / "inverter.yaml"
    path.write_text(yaml.safe_dump(MAPPING), encoding="utf-8")
    sim = Simulator([SimulatedUnit(UNIT, load_mapping(path))])
    sim.set_value(UNIT, "work_mode", "self_use")
    sim.set_value(UNIT, "breaker_raw", 0x0200)
    async with serving_tcp(sim) as port:
        data = {
            "bridge": {
                "gateway": {
                    "enabled": True,
                    "port": 0,
                    "allow_writes": True,
                    "units": {1: "inverter"},
                }
            },
            "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}],
            "devices": [{"id": "inverter", "bus": "tcp", "unit": UNIT, "mapping": "inverter.yaml"}],
        }
        async with gateway_for(data, tmp_path) as (gateway, engine), master(gateway) as client:
            state = engine.devices["inverter"].state
            await eventually(lambda: state.values.get("work_mode") == "self_use", 10)
            written = len(sim.writes)
            answer = await client.write_register(MODE, 2, device_id=UNIT)
            assert not answer.isError()
            assert sim.writes[written:] == [(UNIT, Write(6, H, MODE, (2,)))]
            views = {k: state.values[k] for k in VIEWS}
            assert views == {
                "work_mode_raw": 2,
                "work_mode": "feed_in",
                "backup": False,
                "feeding_in": True,
            }
            written = len(sim.writes)
            for word in (0x0100, 0x0400):  # the breaker's ON word, any other word
                assert (await client.write_register(BREAKER, word, device_id=UNIT)).isError()
            assert sim.writes[written:] == []
            assert not (await client.write_register(BREAKER, 0x0300, device_id=UNIT)).isError()
            assert sim.writes[written:] == [(UNIT, Write(6, H, BREAKER, (0x0300,)))]
