"""The web page in a real browser: headless Chromium (Debian's ``chromium``; .ci/run installs
it) against a running bridge, the simulator and a private Mosquitto.

What a technician at the cabinet would check: a value changes on screen, an alarm is
highlighted, a device goes offline and comes back, a bus scan finds the units, all
operated from the keyboard. Skipped where Chromium is absent.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from bridge.modbus.simulator import Quirks
from tests.integration.browser import CHROMIUM, Page, browser, png_text, png_with_text
from tests.integration.mosquitto import Broker
from tests.integration.web import PUMP, demo_site, site

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)"
)
SCREENSHOTS = os.environ.get("BRIDGE_SCREENSHOTS")  # a folder: keep the screenshots there
README_SHOT = Path(__file__).parents[2] / "docs" / "web-devices.png"
UPDATE = os.environ.get("UPDATE_SCREENSHOTS") == "1"  # write README_SHOT even if it matches


def text(selector: str) -> str:
    """A JavaScript expression: the text of the element ``selector`` finds, or ''."""
    return f"(document.querySelector({selector!r})?.textContent ?? '').trim()"


async def device_state(page: Page, expected: str) -> None:
    await page.until(f"{text('#device-facts dd.state')} === {expected!r}", timeout=20)


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_a_technician_sees_values_change_a_device_drop_out_and_a_scan(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with site(mosquitto, tmp_path) as s, browser(tmp_path) as page:
        home = f"http://127.0.0.1:{s.port}/"
        await page.goto(home)
        pump_state = text('#devices tr[data-device="pump"] .state')
        await page.until(f"{pump_state} === 'online'")
        starter_state = text('#devices tr[data-device="starter"] .state')
        await page.until(f"{starter_state} === 'online'")
        # the devices answer before the session is up (it reads its retained state first)
        await page.until(f"{text('#link')} === 'MQTT online · page live'")
        await _screenshot(page, tmp_path, "web-devices.png")
        # everything it loaded came from the bridge: no CDN, no web fonts
        loaded = await page.evaluate("performance.getEntriesByType('resource').map(e => e.name)")
        assert loaded and all(url.startswith(home) for url in loaded), loaded
        # on a phone the page itself never scrolls sideways (wide tables scroll in place)
        await page.send(
            "Emulation.setDeviceMetricsOverride",
            width=360,
            height=740,
            deviceScaleFactor=2,
            mobile=True,
        )
        await page.until("document.documentElement.scrollWidth <= window.innerWidth")

        # the devices page links to each device; follow the link from the keyboard
        await page.evaluate("document.querySelector('#devices a[href=\"#/device/pump\"]').focus()")
        await page.press("Enter", 13)
        await page.until(f"{text('#device-title')} === 'Pump'")
        assert await page.evaluate("document.activeElement.id") == "device-title"

        value = text('#values tr[data-key="motor_current"] .value')
        s.sim.set_value(PUMP, "motor_current", 12.3)
        await page.until(f"{value} === '12.3'")
        s.sim.set_value(PUMP, "motor_current", 4.2)
        await page.until(f"{value} === '4.2'")
        unit = await page.evaluate(text('#values tr[data-key="motor_current"] td:nth-child(3)'))
        assert unit == "A"

        dry = '#values tr[data-key="alarm_dry_running"]'
        s.sim.set_value(PUMP, "alarm_dry_running", True)
        await page.until(f"document.querySelector({dry!r})?.classList.contains('alarm')")
        assert "ALARM" in await page.evaluate(text(dry))
        # the change arrives in Home Assistant's words: an alarm bit is a problem sensor
        assert await page.evaluate(text(f"{dry} .value")) == "Problem"
        alarms = await page.until(text("#device-alarms"))
        assert alarms == "Active alarms: Dry running"  # the name Home Assistant shows
        assert await page.evaluate("document.querySelector('#device-alarms').title") == (
            "alarm_dry_running"  # the key MQTT clients match
        )

        await device_state(page, "online")
        s.sim.set_quirks(PUMP, Quirks(dead=True))
        await device_state(page, "offline")
        s.sim.set_quirks(PUMP, Quirks())
        await device_state(page, "online")

        await page.goto(home + "#/commission")
        await page.until(f"{text('#scan-bus')} === 'tcp'")
        await page.evaluate(
            "(() => { const units = document.querySelector('#scan-units');"
            " units.value = '1-5'; units.focus(); })()"
        )
        await page.press("Enter", 13)  # submits the scan form from the keyboard
        starter = text('#scan-result tr[data-unit="3"]')
        await page.until(f"{starter}.includes('starter')", timeout=20)
        assert await page.evaluate(text("#scan-status")) == "2 of 5 units answered on tcp"
        assert "pump" in await page.evaluate(text('#scan-result tr[data-unit="1"]'))
        identified = text('#scan-result tr[data-unit="3"] td.identity')
        await page.until(f"{identified}.startsWith('answers like')", timeout=30)
        assert "(soft_starter)" in await page.evaluate(identified)
        await _screenshot(page, tmp_path, "web-commissioning.png")


# What the devices page says, in words, without what changes from run to run (the time of
# the last answer, latency, counts): the title bar, the pages, the table's headings and each
# device's name, model, bus and unit, state and status (with the key in its title).
PAGE_WORDS = """(() => {
  const words = (nodes) => [...nodes].map((n) => n.textContent.trim() + (n.title ? ` (${n.title})` : ""));
  const rows = [...document.querySelectorAll("#devices tbody tr")];
  return [
    words(document.querySelectorAll("header h1, #link")).join(" · "),
    words(document.querySelectorAll("nav a")).join(" | "),
    words(document.querySelectorAll("#devices-title, #devices thead th")).join(" | "),
    ...rows.map((tr) => words([...tr.cells].slice(0, 5)).join(" | ")),
  ].join("\\n");
})()"""


@pytest.mark.asyncio
@pytest.mark.timeout(120)
async def test_the_readme_screenshot_is_the_devices_page_of_today(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """The demo's five seed devices on the page, in Home Assistant's words (the P2 drive
    ``Running forward``, not ``running_forward``); docs/web-devices.png (the README's
    screenshot) is this page: it carries the page's words, and is written anew from the
    running page when they differ (the test then fails: commit the new image) or when
    ``UPDATE_SCREENSHOTS=1``."""
    async with demo_site(mosquitto, tmp_path) as s, browser(tmp_path) as page:
        await page.goto(f"http://127.0.0.1:{s.port}/")
        read = "[...document.querySelectorAll('#devices td.status')].map((c) => c.dataset.value)"
        await page.until(f"{read}.length === 5 && {read}.every((v) => v)", timeout=40)
        states = "[...document.querySelectorAll('#devices td.state')].map((c) => c.textContent)"
        await page.until(f"{states}.every((state) => state === 'online')", timeout=20)
        await page.until(f"{text('#link')} === 'MQTT online · page live'")

        fan = '#devices tr[data-device="fan_drive"] td.status'
        assert await page.evaluate(text(fan)) == "Running forward"
        assert await page.evaluate(f"document.querySelector({fan!r}).title") == "running_forward"
        shown = await page.evaluate(text("#devices tbody"))
        for key in ("running_forward", "no_fault", "normal_running", "true"):
            assert key not in shown, shown
        words = await page.evaluate(PAGE_WORDS)
        shot = tmp_path / "web-devices.png"
        await page.screenshot_whole(shot, 1200)

        kept = png_text(README_SHOT.read_bytes(), "page") if README_SHOT.exists() else None
        if UPDATE or kept != words:
            README_SHOT.write_bytes(png_with_text(shot.read_bytes(), "page", words))
        assert UPDATE or kept == words, (
            f"{README_SHOT} showed an older page; written anew from this one: commit it"
            f"\n--- it showed:\n{kept}\n--- the page shows:\n{words}"
        )

        await page.goto(f"http://127.0.0.1:{s.port}/#/device/fan_drive")
        await page.until(f"{text('#device-facts dd.status')} === 'Running forward'")
        for key, words_of_it, value in (
            ("status", "Running forward", "running_forward"),
            ("fault_code", "No fault", "no_fault"),
            ("running", "Running", "true"),  # a binary sensor of class running, as HA shows it
        ):
            cell = f'#values tr[data-key="{key}"] .value'
            assert await page.evaluate(text(cell)) == words_of_it, key
            assert await page.evaluate(f"document.querySelector({cell!r}).dataset.value") == value


async def _screenshot(page: Page, folder: Path, name: str) -> None:
    path = folder / name
    await page.screenshot(path, 1200, 700)
    assert path.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    if SCREENSHOTS:
        shutil.copy(path, Path(SCREENSHOTS) / name)
