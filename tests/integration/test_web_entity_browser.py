"""A register to an entity in a real browser: headless Chromium on a running bridge with a
simulated seed device (the genset), a private Mosquitto behind.

Read a free register raw, add it as an entity with a scale and a unit, watch the preview
say what Home Assistant will show, add it: the device polls it and its discovery carries
it. Skipped where Chromium is absent.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from bridge.config import MqttConfig
from bridge.core.entity import Table
from bridge.mqtt import MqttClient
from tests.integration.browser import CHROMIUM, Page, browser
from tests.integration.entity_site import FREE, GENSET, STATE, genset_site
from tests.integration.mosquitto import Broker
from tests.integration.web import http

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)"
)
DISCOVERY = "homeassistant/device/genset/config"


def text(selector: str) -> str:
    return f"(document.querySelector({selector!r})?.textContent ?? '').trim()"


async def fill(page: Page, selector: str, value: str) -> None:
    """Type ``value`` into a field as a user would: the page hears an input event."""
    await page.evaluate(
        f"(() => {{ const f = document.querySelector({selector!r}); f.value = {value!r};"
        " f.dispatchEvent(new Event('input', { bubbles: true })); })()"
    )


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_a_raw_register_is_added_as_an_entity_from_the_page(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with (
        genset_site(mosquitto, tmp_path) as s,
        browser(tmp_path) as page,
        MqttClient(MqttConfig(url=mosquitto.url), will_topic="test/ha/state") as home_assistant,
    ):
        s.sim._device(GENSET).image[(Table.HOLDING, FREE)] = 2315  # what the unit holds there
        await home_assistant.subscribe(DISCOVERY)
        await page.goto(f"http://127.0.0.1:{s.port}/#/commission")
        await page.until(
            "[...(document.querySelector('#read-device')?.options ?? [])]"
            ".some(o => o.value === 'genset')"
        )
        await page.evaluate(
            "(() => { const f = document.querySelector('#read-form');"
            f" f.elements.device.value = 'genset'; f.elements.address.value = '{FREE}';"
            " f.elements.count.value = '1'; f.requestSubmit(); })()"
        )
        await page.until(f"{text('#read-result')}.includes('2315')")
        await page.until("!document.querySelector('#entity-form')?.hidden")
        assert await page.evaluate("document.querySelector('#entity-address').value") == str(FREE)

        await fill(page, "#entity-name", "Spare voltage")
        assert await page.evaluate("document.querySelector('#entity-key').value") == (
            "spare_voltage"  # the key follows the name until it is edited
        )
        await page.until(f"{text('#entity-preview')} === '2315'")  # u16, scale 1, no unit
        await fill(page, "#entity-scale", "0.1")
        await fill(page, "#entity-unit", "V")
        await fill(page, "#entity-device_class", "voltage")
        await page.until(f"{text('#entity-preview')} === '231.5 V'")
        await fill(page, "#entity-type", "s32")  # two registers: one was read, so read once
        wide = f"{(2315 << 16) / 10:.1f} V"  # registers 32 and 33 (0) as one s32, x 0.1
        await page.until(f"{text('#entity-preview')} === {wide!r}")
        await fill(page, "#entity-type", "u16")
        await page.until(f"{text('#entity-preview')} === '231.5 V'")

        await page.evaluate("document.querySelector('#entity-form button').click()")
        await page.until(f"{text('#entity-status')}.startsWith('added spare_voltage')", timeout=20)
        assert "state/mappings/genset.yaml" in await page.evaluate(text("#entity-status"))

        async with asyncio.timeout(20):
            while True:
                document = (await http(s.port, "GET", "/api/devices/genset")).json()
                found = {v["key"]: v for v in document["values"]}.get("spare_voltage")
                if found is not None and found["value"] == 231.5:
                    break
                await asyncio.sleep(0.1)
        assert (found["text"], found["unit"]) == ("231.5", "V")
        async with asyncio.timeout(10):
            async for message in home_assistant.messages():
                components = json.loads(message.payload or b"{}").get("cmps", {})
                if "spare_voltage" in components:
                    break
        assert components["spare_voltage"]["unit_of_measurement"] == "V"
        assert components["spare_voltage"]["device_class"] == "voltage"
    assert (tmp_path / STATE / "mappings" / "genset.yaml").is_file()
