"""SIGHUP reads the config file again (what changed applied live) and the mapping files, and
the bridge goes on; it used to end the process.

Found by the soak (bench/soak_faults.py, issue 38): ``kill -HUP`` (``systemctl reload``,
logrotate's postrotate, a closed terminal) took SIGHUP's default, so the bridge ended at
once without a farewell, its devices left ``online`` and its commands unserved.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
from pathlib import Path

import pytest

from tests.integration.harness import serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.test_stop_race import (
    bridge_process,
    catching_sigterm,
    pump_config,
    retained_online,
)


@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_sighup_reloads_the_mappings_and_the_bridge_goes_on(
    mosquitto: Broker, tmp_path: Path
) -> None:
    async with contextlib.AsyncExitStack() as stack:
        port = await stack.enter_async_context(serving_tcp(simulator((1, "nastec_vasco"))))
        process = await stack.enter_async_context(
            bridge_process(tmp_path, pump_config(mosquitto.url, port))
        )
        assert process.stderr is not None
        await catching_sigterm(process.pid)
        await retained_online(mosquitto)

        process.send_signal(signal.SIGHUP)
        lines: list[str] = []
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(5):
                while "SIGHUP: mappings changed" not in "".join(lines):
                    line = await process.stderr.readline()
                    if not line:  # the process ended
                        await process.wait()
                        break
                    lines.append(line.decode(errors="replace"))

        assert process.returncode is None, "".join(lines)[-3000:]
        assert "SIGHUP: mappings changed: none" in "".join(lines)
        await retained_online(mosquitto)  # still serving


async def lines_until(process: asyncio.subprocess.Process, text: str, lines: list[str]) -> None:
    """Read the process's log into ``lines`` until ``text`` shows (bounded), or it ends."""
    assert process.stderr is not None
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(10):
            while text not in "".join(lines):
                line = await process.stderr.readline()
                if not line:
                    return
                lines.append(line.decode(errors="replace"))


@pytest.mark.asyncio
@pytest.mark.timeout(90)
async def test_sighup_applies_the_config_file_and_a_bad_one_changes_nothing(
    mosquitto: Broker, tmp_path: Path
) -> None:
    """SIGHUP reads the config file again and applies what changed (bridge/reconfigure.py):
    a device added is polled; a file that does not load is said in the log, and nothing
    changes."""
    async with contextlib.AsyncExitStack() as stack:
        sim = simulator((1, "nastec_vasco"), (3, "soft_starter"))
        port = await stack.enter_async_context(serving_tcp(sim))
        config = pump_config(mosquitto.url, port)
        process = await stack.enter_async_context(bridge_process(tmp_path, config))
        await catching_sigterm(process.pid)
        await retained_online(mosquitto)
        starter = {"id": "starter", "bus": "tcp", "unit": 3, "mapping": "soft_starter"}
        config["devices"].append(starter)
        (tmp_path / "config.yaml").write_text(json.dumps(config))
        lines: list[str] = []

        process.send_signal(signal.SIGHUP)
        await lines_until(process, "SIGHUP: mappings changed", lines)

        assert "SIGHUP: config changes: devices added: starter" in "".join(lines)
        await retained_online(mosquitto, "starter")  # polled, published
        (tmp_path / "config.yaml").write_text("devices: [\n")
        lines.clear()
        process.send_signal(signal.SIGHUP)
        await lines_until(process, "SIGHUP: mappings changed", lines)

        log = "".join(lines)
        assert "SIGHUP: the config file is not applied, nothing changed" in log
        assert process.returncode is None, log[-3000:]
        await retained_online(mosquitto)  # still serving
