""" "Add a device" in a real browser (headless Chromium, as tests/integration/test_web_browser.py):
a technician picks a TCP gateway the bridge does not know yet, scans it, sees the unit
identified with its confidence, gets the identified mapping preselected and tries it:
the decoded values appear, with their units, and nothing was written or added; then saves
it: the config file gets it (and its bus), and the bridge polls it at once.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from bridge.core.mapping import shipped_library
from bridge.modbus.simulator import Quirks
from tests.integration.browser import CHROMIUM, Page, browser
from tests.integration.mosquitto import Broker
from tests.integration.test_web_add import NEW_UNIT, new_bus
from tests.integration.test_web_save import added_lines, file_site

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)"
)
SCREENSHOTS = os.environ.get("BRIDGE_SCREENSHOTS")  # a folder: keep the screenshot there


def text(selector: str) -> str:
    """A JavaScript expression: the text of the element ``selector`` finds, or ''."""
    return f"(document.querySelector({selector!r})?.textContent ?? '').trim()"


async def fill(page: Page, selector: str, value: str) -> None:
    """Set a field as typing would (its ``input`` and ``change`` events fire)."""
    await page.evaluate(
        f"(() => {{ const f = document.querySelector({selector!r}); f.value = {json.dumps(value)};"
        " f.dispatchEvent(new Event('input', {bubbles: true}));"
        " f.dispatchEvent(new Event('change', {bubbles: true})); })()"
    )


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_a_technician_adds_a_device_from_a_scan_to_a_trial_poll(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with (
        file_site(mosquitto, tmp_path) as s,
        new_bus() as (sim, bus),
        browser(tmp_path) as page,
    ):
        before = s.path.read_text()
        await page.goto(f"http://127.0.0.1:{s.port}/#/add")
        await page.until("document.querySelector('#add-bus')?.options.length >= 3")
        await page.until(f"{text('#add-mapping option')} !== ''")  # the library is listed
        await fill(page, "#add-bus", "\u0000tcp")
        await page.until("!document.querySelector('#add-host').closest('.field').hidden")
        await fill(page, "#add-host", str(bus["host"]))
        await fill(page, "#add-tcp-port", str(bus["tcp_port"]))
        await fill(page, "#add-units", "1-6")
        await page.evaluate("document.querySelector('#add-units').focus()")
        await page.press("Enter", 13)  # submits the scan from the keyboard

        identity = text(f'#add-found tr[data-unit="{NEW_UNIT}"] td.identity')
        await page.until(f"{identity}.includes('nastec_vasco')", timeout=30)
        shown = await page.evaluate(identity)
        assert "Nastec" in shown and any(w in shown for w in ("high", "medium", "low")), shown
        assert (
            await page.evaluate(text("#add-scan-status")) == "1 of 6 units answered on the new bus"
        )
        # the one unit found is taken, with the mapping it was identified as
        await page.until("document.querySelector('#add-mapping').value === 'nastec_vasco'")
        assert await page.evaluate("document.querySelector('#add-unit').value") == str(NEW_UNIT)
        # the mapping's model variants, each a choice with its default
        family = "document.querySelector('#add-option-family')"
        await page.until(f"{family}?.value === 'vasco'")
        choices = await page.evaluate(f"[...{family}.options].map(o => o.value)")
        assert choices == ["vasco", "mida"]
        assert await page.evaluate("document.querySelector('#add-id').value") == (
            f"nastec_vasco_{NEW_UNIT}"
        )

        sim.set_value(NEW_UNIT, "motor_current", 7.5)
        dc_bus = shipped_library()["nastec_vasco"].points({})["dc_bus_voltage"]
        sim.set_quirks(NEW_UNIT, Quirks(refused=frozenset({dc_bus.address})))
        await page.evaluate("document.querySelector('#add-device-form button').click()")
        current = '#add-values tr[data-key="motor_current"]'
        await page.until(f"{text(current + ' .value')} === '7.5'", timeout=30)
        assert await page.evaluate(text(current + " td:nth-child(3)")) == "A"
        refused = await page.evaluate(text("#add-refused"))
        assert refused == f"Refused by the device: holding {dc_bus.address}", refused
        status = await page.evaluate(text("#add-trial-status"))
        assert status.startswith("Nastec VASCO") and "values read" in status, status
        assert not sim.writes and not s.sim.writes
        assert set(s.bridge.engine.devices) == {"pump", "starter"}
        assert s.path.read_text() == before  # tried, not saved

        # Save: the device and its new bus go to the config file and the bridge polls it
        await page.until("!document.querySelector('#add-bus-id-field').hidden")
        await fill(page, "#add-bus-id", "gw2")
        await page.evaluate("document.querySelector('#add-save').click()")
        saved = text("#add-save-status")
        await page.until(f"{saved}.startsWith('Saved and applied')", timeout=30)
        assert "devices added: nastec_vasco_5" in await page.evaluate(saved)
        added = added_lines(before, s.path.read_text())  # the user's file, comments kept
        assert "  - id: gw2" in added and f"  - id: nastec_vasco_{NEW_UNIT}" in added, added
        await page.evaluate("document.querySelector('#add-save-status a').click()")
        await page.until(f"{text('#device-facts dd.state')} === 'online'", timeout=20)
        assert set(s.bridge.engine.devices) == {"pump", "starter", f"nastec_vasco_{NEW_UNIT}"}
        assert not sim.writes and not s.sim.writes
        await page.goto(f"http://127.0.0.1:{s.port}/#/add")
        shot = tmp_path / "web-add.png"
        await page.screenshot(shot, 1200, 900)
        assert shot.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
        if SCREENSHOTS:
            shutil.copy(shot, Path(SCREENSHOTS) / shot.name)
        # on a phone the page itself never scrolls sideways (wide tables scroll in place)
        await page.send(
            "Emulation.setDeviceMetricsOverride",
            width=360,
            height=740,
            deviceScaleFactor=2,
            mobile=True,
        )
        await page.until("document.documentElement.scrollWidth <= window.innerWidth")
