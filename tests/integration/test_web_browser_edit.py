"""The Edit panel in a real browser (headless Chromium, as tests/integration/test_web_browser.py)
on a running bridge started from a commented config file: a technician logs in with the
token, renames a device and changes its fast interval, turns dangerous writes on after
reading what they permit, disables a device and enables it again from the Devices page,
and removes one; the config file holds each change and nothing else.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from tests.integration.browser import CHROMIUM, Page, browser
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.reconfigure_site import Untouched
from tests.integration.web import TOKEN
from tests.integration.web_edit_site import EditSite, edit_site

pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)"),
    pytest.mark.asyncio,
    pytest.mark.timeout(120),
]  # fmt: skip
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


async def click(page: Page, selector: str) -> None:
    await page.evaluate(f"document.querySelector({selector!r}).click()")


async def open_edit(page: Page, here: EditSite, device_id: str) -> None:
    """The device's page with its Edit panel open and filled."""
    await page.goto(f"http://127.0.0.1:{here.port}/#/device/{device_id}")
    await page.until(f"document.querySelector('#edit-id')?.value === {device_id!r}")
    await page.evaluate("document.querySelector('#edit').open = true")


async def login(page: Page, here: EditSite) -> None:
    await page.goto(f"http://127.0.0.1:{here.port}/#/devices")
    await page.until("document.querySelector('#login')?.hidden === false")
    await fill(page, "#token", TOKEN)
    await click(page, "#login-form button")
    await page.until("document.querySelector('#devices tbody').rows.length === 3")


async def test_rename_and_a_faster_poll_from_the_edit_panel(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with edit_site(mosquitto, tmp_path) as here, browser(tmp_path) as page:
        await login(page, here)
        await open_edit(page, here, "pump")
        assert await page.evaluate("document.querySelector('#edit-name').value") == "Borehole pump"
        untouched = Untouched.of(here, "drive", "starter")
        await fill(page, "#edit-name", "Well pump")
        await fill(page, "#edit-fast", "1")
        await click(page, "#edit-form button[type=submit]")

        await page.until(f"{text('#edit-status')}.startsWith('Saved:')")
        status = await page.evaluate(text("#edit-status"))
        assert '"Borehole pump" -> "Well pump"' in status and "poll.fast" in status, status
        await page.until(f"{text('#device-title')} === 'Well pump'")
        pump = here.bridge.engine.devices["pump"].device
        assert (pump.name, pump.poll.fast) == ("Well pump", 1.0)
        assert here.diff() == (
            ["    name: Borehole pump   # as Home Assistant shows it",
             "    poll: {fast: 0.5, slow: 5}"],
            ["    name: Well pump       # as Home Assistant shows it",
             "    poll: {fast: 1, slow: 5}"],
        )  # fmt: skip
        await untouched.check()
        shot = tmp_path / "web-edit.png"
        await page.screenshot(shot, 1200, 900)
        if SCREENSHOTS:
            shutil.copy(shot, Path(SCREENSHOTS) / shot.name)


async def test_dangerous_writes_are_confirmed_on_the_page_naming_what_they_permit(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with edit_site(mosquitto, tmp_path) as here, browser(tmp_path) as page:
        await login(page, here)
        await open_edit(page, here, "drive")
        await page.evaluate("document.querySelector('#edit-dangerous').checked = true")
        await click(page, "#edit-form button[type=submit]")

        await page.until("!document.querySelector('#edit-confirm').hidden")
        listed = await page.evaluate(
            "[...document.querySelectorAll('#edit-confirm-list li')].map(li => li.textContent)"
        )
        assert listed == [
            "Reverse direction",
            "Speed reference (values below 0)",
            "Response to fieldbus fault",
            "Response to slot fault",
        ]
        assert not here.bridge.engine.devices["drive"].device.allow_dangerous_writes
        assert here.diff() == ([], [])
        assert await page.evaluate("document.activeElement.id") == "edit-confirm-no"
        await page.evaluate("document.querySelector('#edit-confirm').scrollIntoView()")
        shot = tmp_path / "web-edit-dangerous.png"
        await page.screenshot(shot, 1000, 700)
        if SCREENSHOTS:
            shutil.copy(shot, Path(SCREENSHOTS) / shot.name)
        await click(page, "#edit-confirm-yes")
        await page.until(f"{text('#edit-status')}.startsWith('Saved:')")
        assert here.bridge.engine.devices["drive"].device.allow_dangerous_writes
        assert here.diff() == ([], ["    allow_dangerous_writes: true"])


async def test_disable_enable_and_remove_from_the_page(mosquitto: Broker, tmp_path: Path) -> None:
    async with edit_site(mosquitto, tmp_path) as here, browser(tmp_path) as page:
        await login(page, here)
        await open_edit(page, here, "drive")
        await page.evaluate("document.querySelector('#edit-enabled').checked = false")
        await click(page, "#edit-form button[type=submit]")
        await page.until(f"{text('#edit-status')}.startsWith('Saved:')")
        assert "drive" not in here.bridge.engine.devices

        await page.goto(f"http://127.0.0.1:{here.port}/#/devices")
        enable = "#not-polled li[data-device=drive] button"
        await page.until(f"document.querySelector({enable!r}) !== null")
        await click(page, enable)
        await eventually(lambda: "drive" in here.bridge.engine.devices)
        await page.until("document.querySelector('#not-polled').hidden")
        assert here.diff() == ([], ["    enabled: true"])

        untouched = Untouched.of(here, "pump", "drive")
        await open_edit(page, here, "starter")
        await click(page, "#edit-remove")
        await page.until("!document.querySelector('#edit-confirm').hidden")
        question = await page.evaluate(text("#edit-confirm-question"))
        assert question.startswith("Remove Starter from the config?"), question
        await click(page, "#edit-confirm-yes")
        await page.until("location.hash === '#/devices'")
        await eventually(lambda: "starter" not in here.bridge.engine.devices)
        await page.until("document.querySelector('#devices tbody').rows.length === 2")
        assert "id: starter" not in here.path.read_text(encoding="utf-8")
        await untouched.check()
