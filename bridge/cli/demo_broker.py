"""The demo's own broker when none answers: a private ``mosquitto``, else the embedded one.

``private_mosquitto(binary, host, port)`` runs the machine's ``mosquitto`` with a config of
its own in a temporary folder (a loopback listener, anonymous, no persistence), waits
until it accepts connections, and stops it at the end of the block; the system's broker
service and its config are never touched. ``find_mosquitto()`` finds the binary (often in
an ``sbin`` folder that is not on a user's ``PATH``).
"""

from __future__ import annotations

import asyncio
import contextlib
import getpass
import os
import shutil
import tempfile
from collections.abc import AsyncIterator
from pathlib import Path

from bridge.mqtt.broker import BrokerUnavailableError

SBIN = ("/usr/sbin", "/usr/local/sbin", "/opt/homebrew/sbin")
READY_WITHIN = 5.0  # seconds for mosquitto to listen
STOP_WITHIN = 5.0


def find_mosquitto() -> Path | None:
    """The ``mosquitto`` binary on ``PATH`` or in the usual sbin folders, if any."""
    found = shutil.which("mosquitto") or shutil.which("mosquitto", path=os.pathsep.join(SBIN))
    return None if found is None else Path(found)


def mosquitto_config(host: str, port: int, log: Path) -> str:
    """A broker for this demo alone: one loopback listener, anonymous, nothing kept."""
    lines = [
        f"listener {port} {host}",
        "allow_anonymous true",
        "persistence false",
        f"log_dest file {log}",
        "log_type error warning notice",
    ]
    if os.geteuid() == 0:  # as root mosquitto would switch to the user 'mosquitto'
        lines.append(f"user {getpass.getuser()}")
    return "\n".join(lines) + "\n"


@contextlib.asynccontextmanager
async def private_mosquitto(binary: Path, host: str, port: int) -> AsyncIterator[str]:
    """Run ``binary`` on ``host:port`` for the block; yield ``mqtt://host:port``."""
    with tempfile.TemporaryDirectory(prefix="modbus-mqtt-bridge-demo-") as folder:
        config, log = Path(folder) / "mosquitto.conf", Path(folder) / "mosquitto.log"
        config.write_text(mosquitto_config(host, port, log))
        process = await asyncio.create_subprocess_exec(
            str(binary),
            "-c",
            str(config),
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.DEVNULL,
            stderr=asyncio.subprocess.PIPE,
        )
        try:
            await _listening(process, host, port, log)
            yield f"mqtt://{host}:{port}"
        finally:
            await _stop(process)


async def _listening(process: asyncio.subprocess.Process, host: str, port: int, log: Path) -> None:
    """Return once ``host:port`` accepts a connection; BrokerUnavailableError if mosquitto
    exits or does not listen in time (with the reason it logged)."""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(READY_WITHIN):
            while process.returncode is None:
                try:
                    _, writer = await asyncio.open_connection(host, port)
                except OSError:
                    await asyncio.sleep(0.05)
                    continue
                writer.close()
                with contextlib.suppress(OSError):
                    await writer.wait_closed()
                return
    await _stop(process)
    said = await process.stderr.read() if process.stderr else b""
    logged = log.read_text(errors="replace") if log.exists() else ""
    reason = (said.decode(errors="replace") + logged).strip().splitlines()
    raise BrokerUnavailableError(
        f"mosquitto did not start on {host}:{port}: {reason[-1] if reason else 'no reason given'}"
    )


async def _stop(process: asyncio.subprocess.Process) -> None:
    if process.returncode is not None:
        return
    process.terminate()
    try:
        async with asyncio.timeout(STOP_WITHIN):
            await process.wait()
    except TimeoutError:
        process.kill()
        await process.wait()
