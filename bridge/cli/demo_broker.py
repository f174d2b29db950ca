"""The demo's broker: the one given, a local one that answers, else its own (a private
``mosquitto``, else the embedded one).

``choose_broker(url, local, embedded)`` picks it (``BrokerChoice``: its URL and how it was
chosen); ``broker_advice`` says once what to do when it cannot be used.

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
import socket
import tempfile
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

from bridge.cli.demo_site import LOOPBACK
from bridge.config import MqttConfig
from bridge.errors import BridgeError
from bridge.mqtt import MqttConnectError
from bridge.mqtt.broker import PROTOCOL, BrokerUnavailableError, embedded_broker

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


@dataclass(frozen=True, slots=True)
class BrokerChoice:
    url: str
    how: str  # "given", "local", PRIVATE or EMBEDDED
    protocol: str = "5"

    @property
    def own(self) -> bool:
        """The demo started it: anonymous, on loopback, stopped with the demo."""
        return self.how in (PRIVATE, EMBEDDED)


PRIVATE = "private mosquitto"
EMBEDDED = "embedded"


class DemoBrokerError(BridgeError):
    """The broker the demo chose cannot be used (unreachable, login refused)."""


def broker_how(broker: BrokerChoice, mqtt: MqttConfig) -> str:
    """``local``, ``given, user bridge``: how the broker was chosen, and the login."""
    return broker.how + (f", user {mqtt.username}" if mqtt.username else "")


def broker_advice(failure: Exception, broker: BrokerChoice) -> str:
    """Why the demo cannot use the broker, and what to do, said once."""
    if isinstance(failure, MqttConnectError) and failure.refused:  # the login
        hint = "log in with --username and --password-file or --password-env"
    elif broker.how == "given":
        hint = "check --mqtt-url, or leave it out to use a local or an embedded broker"
    else:
        hint = "name another broker with --mqtt-url or --local-broker HOST:PORT"
    return f"{failure}\n  {hint}"


@contextlib.asynccontextmanager
async def choose_broker(url: str | None, local: str, embedded: bool) -> AsyncIterator[BrokerChoice]:
    """The broker given, else a local one that answers, else a private mosquitto, else an
    embedded one (both on ``local``'s port if it is free)."""
    if url is not None:
        yield BrokerChoice(url, "given")
        return
    host, _, port_text = local.rpartition(":")
    if await answers(host, int(port_text)):
        yield BrokerChoice(f"mqtt://{host}:{port_text}", "local")
        return
    port = free_port(int(port_text))
    mosquitto = None if embedded else find_mosquitto()
    if mosquitto is not None:
        async with private_mosquitto(mosquitto, LOOPBACK, port) as private:
            yield BrokerChoice(private, PRIVATE)
        return
    async with embedded_broker(LOOPBACK, port) as inside:
        yield BrokerChoice(inside, EMBEDDED, PROTOCOL)


async def answers(host: str, port: int) -> bool:
    """True when something accepts a TCP connection on ``host:port`` within a second."""
    try:
        async with asyncio.timeout(1.0):
            _, writer = await asyncio.open_connection(host, port)
    except (OSError, TimeoutError):
        return False
    writer.close()
    with contextlib.suppress(OSError):
        await writer.wait_closed()
    return True


def free_port(preferred: int) -> int:
    """``preferred`` if it can be bound on loopback, else a free port the OS picks."""
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((LOOPBACK, preferred))
        except OSError:
            probe.bind((LOOPBACK, 0))
        return int(probe.getsockname()[1])
