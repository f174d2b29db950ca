"""MQTT brokers besides Mosquitto, each a private instance on free loopback ports.

Never the machine's own services: NATS gets its own config and JetStream folder, RabbitMQ
its own node (name, ports, Erlang port mapper, cookie, mnesia and log folders), amqtt runs
in a child Python. Each has the interface of ``tests.integration.mosquitto.Broker``:
``url``, ``host``, ``port``, ``start()``, ``stop()``, ``restart()`` (same ports, same
data: NATS and RabbitMQ keep retained messages on disk, amqtt and the test Mosquitto do
not) and ``log``. ``available()`` says whether the broker's binary is installed.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from tests.integration.mosquitto import HOST
from tests.ports import free_port


@dataclass
class ServerBroker:
    """A broker process (and its helpers) in its own session, in ``workdir``."""

    workdir: Path
    host: str = HOST
    port: int = 0
    ready_within: float = 20.0
    processes: list[subprocess.Popen[bytes]] = field(default_factory=list)

    name = "broker"

    @property
    def url(self) -> str:
        return f"mqtt://{self.host}:{self.port}"

    @property
    def log(self) -> str:
        path = self.workdir / "broker.log"
        return path.read_text(errors="replace")[-4000:] if path.exists() else ""

    def start(self) -> None:
        if not self.port:
            self.port = free_port()
            self.choose_ports()
        self.prepare()
        self._launch()

    def stop(self) -> None:
        for process in reversed(self.processes):
            _end(process)
        self.processes.clear()

    def restart(self) -> None:
        self.stop()
        self._launch()

    def choose_ports(self) -> None:
        """Pick the broker's other ports (the MQTT port is ``port``)."""

    def prepare(self) -> None:
        """Write the config files into ``workdir``."""

    def commands(self) -> list[list[str]]:
        """The processes to start, in order (the broker last)."""
        raise NotImplementedError

    def environment(self) -> dict[str, str]:
        return dict(os.environ)

    def _launch(self) -> None:
        with (self.workdir / "broker.log").open("ab") as log:
            for command in self.commands():
                self.processes.append(
                    subprocess.Popen(
                        command,
                        stdout=log,
                        stderr=subprocess.STDOUT,
                        env=self.environment(),
                        cwd=self.workdir,
                        start_new_session=True,  # its own process group: stop() ends all
                    )
                )
        deadline = time.monotonic() + self.ready_within
        while time.monotonic() < deadline:
            if any(process.poll() is not None for process in self.processes):
                self.stop()
                raise RuntimeError(f"{self.name} exited on port {self.port}:\n{self.log}")
            if _answers_connect(self.host, self.port):
                return
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"{self.name} did not answer on {self.port} in time:\n{self.log}")

    def exited(self) -> bool:
        """Whether one of its processes has ended (stop() not called)."""
        return any(process.poll() is not None for process in self.processes)


# An MQTT 3.1.1 CONNECT (clean session, keepalive 10 s, client id "ready") and DISCONNECT.
_CONNECT = bytes([0x10, 17, 0, 4]) + b"MQTT" + bytes([4, 0x02, 0, 10, 0, 5]) + b"ready"
_DISCONNECT = bytes([0xE0, 0])


def _answers_connect(host: str, port: int) -> bool:
    """Whether the port answers an MQTT CONNECT with a CONNACK: a broker may take TCP
    connections before it can serve them (RabbitMQ's listener opens during its boot)."""
    try:
        with socket.create_connection((host, port), timeout=1.0) as sock:
            sock.sendall(_CONNECT)
            answer = sock.recv(4)
            if answer[:1] == b"\x20":
                sock.sendall(_DISCONNECT)
            return answer[:1] == b"\x20" and answer[3:4] == b"\x00"
    except OSError:
        return False


def _end(process: subprocess.Popen[bytes]) -> None:
    """SIGTERM to the process group, SIGKILL after 30 s."""
    if process.poll() is not None:
        return
    for signum, wait in ((signal.SIGTERM, 30), (signal.SIGKILL, 10)):
        try:
            os.killpg(process.pid, signum)
        except ProcessLookupError:
            return
        try:
            process.wait(wait)
            return
        except subprocess.TimeoutExpired:
            continue


NATS_SERVER = shutil.which("nats-server") or "/usr/sbin/nats-server"


@dataclass
class NatsBroker(ServerBroker):
    """nats-server with MQTT on (which needs JetStream and a server name)."""

    client_port: int = 0
    name = "nats-server"

    @staticmethod
    def available() -> bool:
        return os.access(NATS_SERVER, os.X_OK)

    @staticmethod
    def version() -> tuple[int, ...]:
        out = subprocess.run([NATS_SERVER, "--version"], capture_output=True, text=True, check=True)
        found = re.search(r"v(\d+)\.(\d+)\.(\d+)", out.stdout)
        return tuple(int(n) for n in found.groups()) if found else (0,)

    def choose_ports(self) -> None:
        self.client_port = free_port()

    def prepare(self) -> None:
        store = self.workdir / "jetstream"
        store.mkdir(exist_ok=True)
        (self.workdir / "nats.conf").write_text(
            f'server_name: "pytest-{os.getpid()}"\n'
            f"listen: {self.host}:{self.client_port}\n"
            f'jetstream {{ store_dir: "{store}" }}\n'
            f"mqtt {{ listen: {self.host}:{self.port} }}\n"
        )

    def commands(self) -> list[list[str]]:
        return [[NATS_SERVER, "-c", str(self.workdir / "nats.conf")]]


RABBITMQ_SERVER = "/usr/lib/rabbitmq/bin/rabbitmq-server"  # the script, not the su wrapper


def _epmd() -> str | None:
    return shutil.which("epmd") or next(iter(glob.glob("/usr/lib/erlang/erts-*/bin/epmd")), None)


@dataclass
class RabbitBroker(ServerBroker):
    """A RabbitMQ node of its own with the MQTT plugin: own node name, AMQP, distribution
    and port mapper ports, own cookie (HOME), mnesia, log, plugins and config files; the
    machine's rabbitmq-env.conf is not read."""

    amqp_port: int = 0
    dist_port: int = 0
    epmd_port: int = 0
    ready_within: float = 90.0
    name = "rabbitmq-server"

    @staticmethod
    def available() -> bool:
        return os.access(RABBITMQ_SERVER, os.X_OK) and _epmd() is not None

    def choose_ports(self) -> None:
        self.amqp_port, self.dist_port, self.epmd_port = free_port(), free_port(), free_port()

    def prepare(self) -> None:
        work = self.workdir
        (work / "rabbitmq.conf").write_text(
            f"mqtt.listeners.tcp.1 = {self.host}:{self.port}\n"
            "mqtt.allow_anonymous = true\n"
            "log.console = true\nlog.console.level = warning\nlog.file = false\n"
        )
        (work / "enabled_plugins").write_text("[rabbitmq_mqtt].\n")
        (work / "rabbitmq-env.conf").write_text("")

    def environment(self) -> dict[str, str]:
        work = str(self.workdir)
        return dict(os.environ) | {
            "HOME": work,  # the Erlang cookie
            "RABBITMQ_CONF_ENV_FILE": f"{work}/rabbitmq-env.conf",
            "RABBITMQ_NODENAME": f"pytest{os.getpid()}@localhost",
            "RABBITMQ_NODE_IP_ADDRESS": self.host,
            "RABBITMQ_NODE_PORT": str(self.amqp_port),
            "RABBITMQ_DIST_PORT": str(self.dist_port),
            "ERL_EPMD_PORT": str(self.epmd_port),
            "ERL_EPMD_ADDRESS": self.host,
            "RABBITMQ_MNESIA_BASE": f"{work}/mnesia",
            "RABBITMQ_LOG_BASE": f"{work}/log",
            "RABBITMQ_ENABLED_PLUGINS_FILE": f"{work}/enabled_plugins",
            "RABBITMQ_CONFIG_FILE": f"{work}/rabbitmq.conf",
            "RABBITMQ_ADVANCED_CONFIG_FILE": f"{work}/advanced.config",
            "RABBITMQ_PID_FILE": f"{work}/rabbitmq.pid",
        }

    def commands(self) -> list[list[str]]:
        epmd = _epmd()
        assert epmd is not None
        # Our own port mapper in the foreground, so that stop() ends it too.
        mapper = [epmd, "-port", str(self.epmd_port), "-address", self.host]
        return [mapper, [RABBITMQ_SERVER]]


@dataclass
class AmqttBroker(ServerBroker):
    """amqtt (the demo extra) in a child Python: the bridge's own embedded broker."""

    name = "amqtt"

    @staticmethod
    def available() -> bool:
        try:
            import amqtt  # noqa: F401, PLC0415
        except ImportError:
            return False
        return True

    def commands(self) -> list[list[str]]:
        script = (
            "import asyncio\n"
            "from bridge.mqtt.broker import embedded_broker\n"
            "async def main():\n"
            f"    async with embedded_broker({self.host!r}, {self.port}):\n"
            "        await asyncio.Event().wait()\n"
            "asyncio.run(main())\n"
        )
        return [[sys.executable, "-c", script]]

    def environment(self) -> dict[str, str]:
        root = str(Path(__file__).resolve().parents[2])
        return dict(os.environ) | {"PYTHONPATH": root}
