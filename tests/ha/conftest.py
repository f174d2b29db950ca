"""Fixtures of the Home Assistant tests: one Home Assistant per module, on the version
``HA_VERSION`` names, installed by ``tools/ha_env.sh`` in the chroot ``HA_ROOT``
(default ``~/.cache/modbus-mqtt-bridge/ha-forky``). ``make test-ha`` sets them; without them the tests are skipped."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.ha.homeassistant import HomeAssistant
from tests.integration.mosquitto import Broker

ROOT = Path(__file__).resolve().parents[2]
HA_CACHE = Path.home() / ".cache" / "modbus-mqtt-bridge" / "ha-forky"  # make test-ha's HA_ROOT


@pytest.fixture(scope="module")
def ha_broker(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Broker]:
    broker = Broker(tmp_path_factory.mktemp("mosquitto"))
    broker.start()
    yield broker
    broker.stop()


def installed_home_assistant() -> tuple[Path, str]:
    """The chroot and the version ``HA_ROOT``/``HA_VERSION`` name; the test is skipped,
    saying why, when that version is not installed or cannot run here."""
    version = os.environ.get("HA_VERSION", "")
    root = Path(os.environ.get("HA_ROOT", HA_CACHE))
    if not version or not (root / f"opt/ha-{version}/.ready").exists():
        pytest.skip("no Home Assistant installed: `make test-ha` installs and runs them")
    if shutil.which("chroot") is None or os.geteuid() != 0:
        pytest.skip("Home Assistant runs in a chroot: needs root")
    return root, version


@pytest.fixture(scope="module")
def hass(request: pytest.FixtureRequest, ha_broker: Broker) -> Iterator[HomeAssistant]:
    """One Home Assistant per test module, with the integrations the module names in
    ``HA_INTEGRATIONS`` (the recorder for the statistics) besides MQTT."""
    root, version = installed_home_assistant()
    ha = HomeAssistant(root, version, integrations=getattr(request.module, "HA_INTEGRATIONS", ()))
    try:
        ha.start()
        ha.add_mqtt(ha_broker.host, ha_broker.port)
        yield ha
    finally:
        ha.stop()
        if os.environ.get("HA_KEEP_CONFIG"):
            print(f"Home Assistant's config folder: {ha.workdir}")
        else:
            ha.remove()
