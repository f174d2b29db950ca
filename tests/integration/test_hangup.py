"""SIGHUP reloads the mapping files and the bridge goes on; it used to end the process.

Found by the soak (bench/soak_faults.py, issue 38): ``kill -HUP`` (``systemctl reload``,
logrotate's postrotate, a closed terminal) took SIGHUP's default, so the bridge ended at
once without a farewell, its devices left ``online`` and its commands unserved.
"""

from __future__ import annotations

import asyncio
import contextlib
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
