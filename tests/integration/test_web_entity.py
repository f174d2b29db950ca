"""A raw register becomes an entity from the page: a real bridge (real Mosquitto, the
simulator behind) with ``bridge.web`` on, asked over plain sockets.

The preview decodes the words a raw read gave; an add writes the device's override file
(never the shipped mapping), the device reloads it, polls the new entity and Home
Assistant's discovery publishes it. Every hostile request is refused with its status and
one log line, and nothing is written.
"""

from __future__ import annotations

import asyncio
import json
import logging
from pathlib import Path
from typing import Any

import pytest

from bridge.config import MqttConfig
from bridge.config.loading import override_path
from bridge.core.entity import Table
from bridge.core.mapping import builtin_mapping_path
from bridge.mqtt import MqttClient
from tests.integration.entity_site import FREE, GENSET, STATE, genset_site
from tests.integration.mosquitto import Broker
from tests.integration.web import Answer, http, parse_answer, request_bytes, site

PROPOSAL = {
    "device": "genset",
    "key": "spare_voltage",
    "name": "Spare voltage",
    "address": FREE,
    "scale": 0.1,
    "unit": "V",
    "device_class": "voltage",
    "state_class": "measurement",
}
DISCOVERY = "homeassistant/device/genset/config"  # device-based discovery


async def read_free(port: int) -> list[int]:
    body = {"device": "genset", "address": FREE, "count": 1}
    read = (await http(port, "POST", "/api/request/device/read", body)).json()
    assert read["status"] == "ok", read
    return list(read["data"]["registers"])


async def value_of(port: int, key: str) -> dict[str, Any] | None:
    document = (await http(port, "GET", "/api/devices/genset")).json()
    return next((v for v in document["values"] if v["key"] == key), None)


@pytest.mark.asyncio
async def test_a_raw_register_becomes_an_entity_home_assistant_discovers(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="bridge.web.entity")
    shipped = builtin_mapping_path("smartgen_hgm6100").read_bytes()
    async with genset_site(mosquitto, tmp_path) as s:
        s.sim._device(GENSET).image[(Table.HOLDING, FREE)] = 2315  # what the unit holds there
        words = await read_free(s.port)
        assert words == [2315]
        preview = await http(s.port, "POST", "/api/entity/preview", PROPOSAL | {"words": words})
        assert preview.status == 200, preview.body
        shown = preview.json()["data"]
        assert (shown["value"], shown["text"], shown["unit"]) == (231.5, "231.5", "V")
        read_once = (await http(s.port, "POST", "/api/entity/preview", PROPOSAL)).json()
        assert read_once["data"]["words"] == [2315]  # no words given: read once

        will = "test/ha/state"
        async with MqttClient(MqttConfig(url=mosquitto.url), will_topic=will) as subscriber:
            await subscriber.subscribe(DISCOVERY)
            added = await http(s.port, "POST", "/api/entity/add", PROPOSAL)
            assert added.status == 200, added.body
            data = added.json()["data"]
            path = override_path(tmp_path / STATE, "genset")
            said = 'entity add from 127.0.0.1: genset.spare_voltage {"entity": {"name"'
            assert said in caplog.text  # who added what, for the site's records
            assert data == {
                "entity": {
                    "name": "Spare voltage",
                    "address": FREE,
                    "scale": 0.1,
                    "unit": "V",
                    "ha": {"device_class": "voltage", "state_class": "measurement"},
                },
                "path": str(path),
                "mapping": "state/mappings/genset.yaml",
                "key": "spare_voltage",
                "changed": ["genset"],
            }
            async with asyncio.timeout(10):
                async for message in subscriber.messages():  # the retained one, then the new
                    components = json.loads(message.payload or b"{}").get("cmps", {})
                    if "spare_voltage" in components:
                        config = components["spare_voltage"]
                        break
        assert config["device_class"] == "voltage"
        assert config["unit_of_measurement"] == "V"
        assert config["unique_id"].endswith("spare_voltage")

        async with asyncio.timeout(10):
            while (found := await value_of(s.port, "spare_voltage")) is None or found[
                "value"
            ] != 231.5:
                await asyncio.sleep(0.05)
        assert found["unit"] == "V"
        first = path.read_text(encoding="utf-8")
        again = await http(s.port, "POST", "/api/entity/add", PROPOSAL)
        assert again.status == 422 and "has this entity already" in again.body.decode()
        assert path.read_text(encoding="utf-8") == first  # a refusal writes nothing
        second = PROPOSAL | {"key": "spare_word", "name": "Spare word", "address": FREE + 1}
        del second["scale"], second["unit"], second["device_class"], second["state_class"]
        added = await http(s.port, "POST", "/api/entity/add", second)
        assert added.status == 200, added.body
        assert path.read_text(encoding="utf-8") == first + (
            "  spare_word:\n    name: Spare word\n    address: 33\n"
        )  # the file as it was, one entity more
        async with asyncio.timeout(10):
            while await value_of(s.port, "spare_word") is None:
                await asyncio.sleep(0.05)
        assert (await value_of(s.port, "spare_voltage")) is not None
        assert not s.sim.writes
    text = path.read_text(encoding="utf-8")
    assert text.splitlines()[2:-3] == [
        "extends: smartgen_hgm6100",
        "entities:",
        "  spare_voltage:",
        "    name: Spare voltage",
        "    address: 32",
        "    scale: 0.1",
        "    unit: V",
        "    ha:",
        "      device_class: voltage",
        "      state_class: measurement",
    ]
    assert builtin_mapping_path("smartgen_hgm6100").read_bytes() == shipped  # never edited


PUMP_PROPOSAL = PROPOSAL | {"device": "pump", "address": 97}  # a free register of the pump
BAD = [
    ("bad JSON", b"{not json", {}, 400, "send a JSON object"),
    ("not an object", [PUMP_PROPOSAL], {}, 400, "send a JSON object"),
    ("bad type", PUMP_PROPOSAL | {"type": "u128"}, {}, 400, "type: Input should be"),
    ("address out of range", PUMP_PROPOSAL | {"address": 70000}, {}, 400, "address: Input should"),
    ("a long name", PUMP_PROPOSAL | {"name": "n" * 1000}, {}, 400, "name: String should have"),
    ("a 1 MB name", PUMP_PROPOSAL | {"name": "n" * 2**20}, {}, 413, "body"),
    ("a bad key", PUMP_PROPOSAL | {"key": "../../etc/passwd"}, {}, 400, "key: String should"),
    ("a key that collides", PUMP_PROPOSAL | {"key": "power"}, {}, 422, "has this entity already"),
    (
        "a dangerous register",
        PUMP_PROPOSAL | {"address": 53},
        {},
        422,
        "sensor_full_scale, dangerous",
    ),
    (
        "a secret register",
        PUMP_PROPOSAL | {"address": 142},
        {},
        422,
        "password_1_left, dangerous",
    ),
    ("no such device", PUMP_PROPOSAL | {"device": "nope"}, {}, 404, "no device 'nope'"),
    ("a bad combination", PUMP_PROPOSAL | {"type": "u16", "count": 2}, {}, 422, "count is given"),
    ("a writable entity", PUMP_PROPOSAL | {"access": "rw"}, {}, 400, "access: Extra inputs"),
    ("too many words", PUMP_PROPOSAL | {"words": [0] * 126}, {}, 400, "words: Tuple should"),
    ("another site", PUMP_PROPOSAL, {"Origin": "http://evil.example"}, 403, "other sites"),
    ("not JSON", PUMP_PROPOSAL, {"Content-Type": "text/plain"}, 415, "send JSON"),
]


async def too_big(
    port: int, method: str, path: str, body: object, headers: dict[str, str]
) -> Answer:
    """A request whose body is over the limit: its head and a first part of the body (the
    server answers 413 at the head and closes; the rest would meet a closed socket)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        raw = request_bytes(method, path, port, body, headers)
        writer.write(raw[: raw.index(b"\r\n\r\n") + 4 + 1000])
        async with asyncio.timeout(10):
            return parse_answer(await reader.read(-1))
    finally:
        writer.close()


@pytest.mark.asyncio
@pytest.mark.timeout(120)
async def test_hostile_input_is_refused_and_nothing_is_written(
    mosquitto: Broker, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    async with site(mosquitto, tmp_path) as s:
        for what, body, headers, status, said in BAD:
            for route in ("/api/entity/preview", "/api/entity/add"):
                caplog.clear()
                with caplog.at_level(logging.INFO, logger="bridge.web"):
                    send = too_big if status == 413 else http
                    answer = await send(s.port, "POST", route, body, headers)
                assert answer.status == status, (what, route, answer.body[:300])
                if status != 413:  # the HTTP layer answers that one before any route
                    assert said in answer.body.decode(), (what, answer.body[:300])
                lines = [r.getMessage() for r in caplog.records if r.name.startswith("bridge.web")]
                if status == 413 and route.endswith("add"):  # bridge/web/http.py logs its
                    assert lines == [], lines  # refusals at most once a minute: no flood
                    continue
                assert len(lines) == 1 and len(lines[0]) < 700, (
                    what,
                    route,
                    [m[:200] for m in lines],
                )
        assert not (tmp_path / "state" / "mappings").exists()
        assert not s.sim.writes
