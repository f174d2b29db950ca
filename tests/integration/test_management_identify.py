"""``bridge/request/device/identify`` over a real Mosquitto, the simulator behind: the same
answer as the command line, never a write, a retained request never run, bad payloads
answered with an error naming the problem."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from bridge.dispatcher import RETAINED
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_management import client_of, online, request, site


@pytest.mark.asyncio
async def test_identify_over_mqtt_tells_the_units(mosquitto: Broker, tmp_path: Path) -> None:
    async with site(mosquitto, tmp_path) as (bridge, sim), client_of(mosquitto) as tester:
        sim.set_value(1, "modbus_address", 1)  # the Nastec's address register reads its unit
        await online(bridge, tester)
        answer = await request(tester, "device/identify", {"units": "1-4", "timeout": 0.3})
        assert answer["status"] == "ok", answer
        data = answer["data"]
        assert (data["bus"], data["probed"], data["max_requests_per_unit"]) == ("tcp", 4, 47)
        found = {item["unit"]: item for item in data["found"]}
        assert sorted(found) == [1, 3]
        assert found[1]["matches"][0]["mapping"] == "nastec_vasco"
        assert found[1]["matches"][0]["level"] == "high"
        assert found[3]["matches"][0]["mapping"] == "soft_starter"
        assert found[3]["summary"].startswith("answers like")
        assert (
            found[3]["config"]
            == "- id: soft_starter_3\n  bus: tcp\n  unit: 3\n  mapping: soft_starter\n"
        )
        one = await request(tester, "device/identify", {"bus": "tcp", "unit": 1})
        assert [item["unit"] for item in one["data"]["found"]] == [1]
        assert sim.writes == []


@pytest.mark.asyncio
async def test_a_retained_identify_request_is_never_run(mosquitto: Broker, tmp_path: Path) -> None:
    topic = "modbus/bridge/request/device/identify"
    async with client_of(mosquitto) as early:  # left on the broker before the bridge starts
        await early.client.publish(
            topic, json.dumps({"unit": 3, "transaction": "old"}), retain=True
        )
    async with site(mosquitto, tmp_path) as (bridge, _), client_of(mosquitto) as tester:
        await online(bridge, tester)
        retained = json.dumps({"unit": 3, "transaction": "retained"})
        await tester.client.publish(topic, retained, retain=True)
        answer = await request(tester, "device/identify", {"unit": 1, "timeout": 0.3})
        assert answer["status"] == "ok"
        await asyncio.sleep(0.5)
        answers = [
            json.loads(m.payload) for m in tester.after(0, "modbus/bridge/response/device/identify")
        ]
        answered = [a["transaction"] for a in answers]
        refusals = [a["error"] for a in answers if a["transaction"] is None]
        assert refusals and all(RETAINED in error for error in refusals), answers
        assert "retained" not in answered and "old" not in answered
        assert answered.count(answer["transaction"]) == 1
        await eventually(lambda: bridge.management._scanning == set(), 5)


@pytest.mark.asyncio
async def test_bad_identify_requests_are_answered_with_an_error(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as (bridge, sim), client_of(mosquitto) as tester:
        await online(bridge, tester)
        garbled = await request(tester, "device/identify", b"{not json")
        assert garbled["status"] == "error" and "not JSON" in garbled["error"]
        cases = [
            ({"unit": 1, "units": "1-3"}, "give unit or units"),
            ({}, "give unit or units"),
            ({"units": "1-100000000"}, "1..247"),
            ({"unit": 0}, "greater than or equal to 1"),
            ({"unit": 1, "timeout": 60}, "timeout"),
            ({"unit": 1, "bus": "nope"}, "no bus 'nope'"),
            ({"unit": 1, "write": True}, "Extra inputs are not permitted"),
        ]
        for body, words in cases:
            answer = await request(tester, "device/identify", body)
            assert answer["status"] == "error" and words in answer["error"], (body, answer)
        assert sim.writes == []
