"""The page's one writer of the config file (bridge/web/config_file.py) with several
changes at once, as "Add a device" on a new bus makes them: a bus, then a device on it,
written in turn and applied together; a refused later change leaves the file and the
running bridge agreeing on the changes before it."""

from __future__ import annotations

from http import HTTPStatus
from pathlib import Path
from typing import Any

import pytest

from bridge.config.edits import AddBus, AddDevice, EditDevice
from bridge.web.config_file import ConfigChangeError, ConfigFile
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.reconfigure_site import Untouched, published
from tests.integration.web_edit_site import EditSite, edit_site

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(120)]


def new_bus(here: EditSite, bus_id: str) -> dict[str, Any]:
    """A second bus to the simulator (as a second gateway would be)."""
    return {"id": bus_id, "transport": "tcp", "host": "127.0.0.1", "tcp_port": here.ports["tcp"]}


async def test_a_bus_and_a_device_on_it_written_in_turn_and_applied_together(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        untouched = Untouched.of(here, "pump", "drive", "starter")
        file = ConfigFile(here.bridge)  # (the page has its own: this test uses no page)
        device = {"id": "well", "bus": "tcp2", "unit": 4, "mapping": "nastec_vasco"}

        changed = await file.change(AddBus(bus=new_bus(here, "tcp2")), AddDevice(device=device))

        assert changed.applied["changes"] == {"buses_added": ["tcp2"], "added": ["well"]}
        assert "add bus tcp2" in changed.line and "add device well" in changed.line
        await eventually(lambda: published(here, ["well"]), timeout=15)
        lost, gained = here.diff()
        assert lost == []
        assert "  - id: tcp2" in gained and "  - id: well" in gained
        await untouched.check()


async def test_a_refused_later_change_leaves_the_earlier_ones_written_and_applied(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with edit_site(mosquitto, tmp_path) as here:
        file = ConfigFile(here.bridge)
        device = {"id": "well", "bus": "tcp3", "unit": 300, "mapping": "nastec_vasco"}

        with pytest.raises(ConfigChangeError) as refused:
            await file.change(AddBus(bus=new_bus(here, "tcp3")), AddDevice(device=device))

        assert refused.value.status == HTTPStatus.BAD_REQUEST
        said = str(refused.value)
        assert "unit" in said and "written and applied" in said and "add bus tcp3" in said
        assert "tcp3" in here.bridge.engine.schedulers
        assert "  - id: tcp3" in here.diff()[1]
        assert "well" not in here.bridge.engine.devices
        # the file and the bridge agree: the next change goes ahead
        renamed = await file.change(EditDevice(id="pump", set={"name": "Well pump"}))
        assert renamed.applied["changes"] == {"restarted": ["pump"]}
