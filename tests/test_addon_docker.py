"""The Home Assistant add-on on a real Docker engine, built and run as the Supervisor
builds and runs it (skipped, saying why, when no Docker engine answers or the local
registry cannot be set up).

The add-on is built by ``.ci/release`` exactly as ``make release-check`` and the release
workflow build it: the project's image pushed to a local registry standing in for
ghcr.io, then the add-on folder built with ``--pull`` and the Supervisor's build
arguments, no override. It runs on a network like the Supervisor's ``hassio`` network
(172.30.32.0/23, the Supervisor at 172.30.32.2, the broker add-on as ``core-mosquitto``)
with a fake Supervisor answering ``GET /services/mqtt`` and the image's own HEALTHCHECK
(30 s apart, 3 retries): what the Supervisor's watchdog reacts to.

    DOCKER_HOST=unix:///tmp/dk-docker/docker.sock .venv/bin/pytest tests/test_addon_docker.py
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import time
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bridge import __version__
from tests.conftest import BROKER_PASSWORD, BROKER_USER
from tests.test_addon import TOKEN
from tests.test_docker import _engine_answers, docker, first_message, health

ROOT = Path(__file__).resolve().parent.parent
ADDON_IMAGE = f"local/amd64-addon-modbus_mqtt_bridge:{__version__}"
SUBNET, GATEWAY = "172.30.32.0/23", "172.30.32.1"
SUPERVISOR_IP, CORE_MOSQUITTO, OTHER_BROKER, SIMULATOR = (
    "172.30.32.2", "172.30.32.10", "172.30.32.11", "172.30.32.20",
)  # fmt: skip
NOBODY = "172.30.33.200"  # in the subnet, no container: a gateway that is unplugged
STAY_UP = 180  # seconds the add-on must stay up, healthy, with one bus unreachable
pytestmark = pytest.mark.timeout(1500)

FAKE_SUPERVISOR = """
import json, os
from http.server import BaseHTTPRequestHandler, HTTPServer
answer = json.loads(os.environ["ANSWER"])
class Handler(BaseHTTPRequestHandler):
    def do_GET(self):
        ok = self.headers.get("Authorization") == "Bearer " + os.environ["TOKEN"]
        status, body = (200, answer) if ok and self.path == "/services/mqtt" else (401, {})
        data = json.dumps(body).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)
HTTPServer(("0.0.0.0", 80), Handler).serve_forever()
"""


def release(step: str) -> None:
    done = subprocess.run(
        [str(ROOT / ".ci" / "release"), step], capture_output=True, text=True, timeout=900,
        check=False, env={**os.environ, "BUILDX": "0"},
    )  # fmt: skip
    if done.returncode != 0:
        raise AssertionError(f".ci/release {step}: {done.returncode}\n{done.stdout}{done.stderr}")


@pytest.fixture(scope="module")
def addon_image() -> str:
    if not _engine_answers():
        pytest.skip(
            "no Docker engine answers (set DOCKER_HOST, or run ../shared/tools/docker-local.sh)"
        )
    if os.geteuid() != 0:
        pytest.skip("the local registry standing in for ghcr.io needs root (/etc/hosts, certs.d)")
    for step in ("image", "registry", "push", "addon"):
        release(step)
    return ADDON_IMAGE


@pytest.fixture(scope="module")
def hassio(addon_image: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The network, two brokers (core-mosquitto with a login, another anonymous), the
    simulator serving a pump and the fake Supervisor naming core-mosquitto."""
    name = f"pytest-hassio-{os.getpid()}"
    folder = tmp_path_factory.mktemp("hassio")
    folder.chmod(0o755)
    passwords = folder / "passwd"
    subprocess.run(["mosquitto_passwd", "-b", "-c", str(passwords), BROKER_USER, BROKER_PASSWORD],
                   check=True, capture_output=True)  # fmt: skip
    (folder / "core.conf").write_text(
        "listener 1883\nallow_anonymous false\npassword_file /mosquitto/config/passwd\n"
    )
    (folder / "other.conf").write_text("listener 1883\nallow_anonymous true\n")
    for file in folder.iterdir():
        file.chmod(0o644)
    answer = {"result": "ok", "data": {"host": "core-mosquitto", "port": 1883, "ssl": False,
              "protocol": "3.1.1", "username": BROKER_USER, "password": BROKER_PASSWORD,
              "addon": "core_mosquitto"}}  # fmt: skip
    containers = []
    docker("network", "create", "--subnet", SUBNET, "--gateway", GATEWAY, name)
    try:
        for container, ip, args in (
            ("core-mosquitto", CORE_MOSQUITTO,
             ["-v", f"{folder}/core.conf:/mosquitto/config/mosquitto.conf:ro",
              "-v", f"{passwords}:/mosquitto/config/passwd:ro", "eclipse-mosquitto:2"]),
            ("other-broker", OTHER_BROKER,
             ["-v", f"{folder}/other.conf:/mosquitto/config/mosquitto.conf:ro",
              "eclipse-mosquitto:2"]),
            ("simulator", SIMULATOR,
             ["--entrypoint", "modbus-mqtt-bridge", addon_image, "simulate", "--tcp", "0.0.0.0:5020", "--mapping", "nastec_vasco", "--unit", "1"]),
            ("supervisor", SUPERVISOR_IP,
             ["-e", f"ANSWER={json.dumps(answer)}", "-e", f"TOKEN={TOKEN}", "--user", "root",
              "--entrypoint", "python", addon_image, "-c", FAKE_SUPERVISOR]),
        ):  # fmt: skip
            full = f"{name}-{container}"
            docker("run", "-d", "--name", full, "--network", name, "--ip", ip, *args)
            containers.append(full)
        yield name
    finally:
        for container in containers:
            docker("rm", "-f", "-v", container, check=False)
        docker("network", "rm", name, check=False)


def options(**extra: Any) -> dict[str, Any]:
    """Two buses: the simulator's gateway, and one nobody answers."""
    return {
        "buses": [{"id": "gw", "transport": "tcp", "host": SIMULATOR, "tcp_port": 5020},
                  {"id": "unplugged", "transport": "tcp", "host": NOBODY, "tcp_port": 502,
                   "timeout": "0.5s"}],
        "devices": [{"id": "pump", "name": "Borehole pump", "bus": "gw", "unit": 1,
                     "mapping": "nastec_vasco"},
                    {"id": "drive", "name": "Drive", "bus": "unplugged", "unit": 2,
                     "mapping": "p2_vfd"}],
        "base_topic": "modbus", "discovery_prefix": "homeassistant", "log_level": "info",
    } | extra  # fmt: skip


def start_addon(network: str, addon_image: str, folder: Path, settings: dict[str, Any]) -> str:
    """The add-on's container as the Supervisor starts it: on the network, the options in
    /data/options.json, the token in SUPERVISOR_TOKEN, `supervisor` and `core-mosquitto`
    resolvable, the image's own HEALTHCHECK."""
    folder.chmod(0o755)
    (folder / "options.json").write_text(json.dumps(settings), encoding="utf-8")
    (folder / "options.json").chmod(0o644)
    name = f"{network}-addon-{len(list(folder.parent.iterdir()))}"
    docker(
        "run", "-d", "--name", name, "--network", network, "--init",
        "--add-host", f"supervisor:{SUPERVISOR_IP}", "--add-host", f"core-mosquitto:{CORE_MOSQUITTO}",
        "-e", f"SUPERVISOR_TOKEN={TOKEN}", "-v", f"{folder / 'options.json'}:/data/options.json:ro",
        addon_image,
    )  # fmt: skip
    return name


def state(container: str) -> dict[str, Any]:
    result: dict[str, Any] = json.loads(
        docker("inspect", "-f", "{{json .State}}", container).stdout
    )
    result["RestartCount"] = int(docker("inspect", "-f", "{{.RestartCount}}", container).stdout)
    return result


def core(host: str) -> Any:
    """A broker on the network, as first_message reads it (host, port)."""
    return types.SimpleNamespace(host=host, port=1883)


def test_the_addon_stays_up_and_healthy_while_one_bus_is_unreachable(
    hassio: str, addon_image: str, tmp_path: Path
) -> None:
    """It asks the fake Supervisor for the broker, publishes discovery and the pump, and
    for three minutes with the other bus unreachable stays running, never restarted,
    healthy (its health log naming the bus down): the watchdog has nothing to restart."""
    name = start_addon(hassio, addon_image, tmp_path, options())
    try:
        login = (BROKER_USER, BROKER_PASSWORD)
        broker = core(CORE_MOSQUITTO)
        config = first_message(broker, "homeassistant/device/pump/config", 60, login=login)
        assert json.loads(config)["device"]["name"] == "Borehole pump"
        assert first_message(broker, "modbus/pump/availability", 30, login=login) == b"online"
        started = state(name)["StartedAt"]
        deadline = time.monotonic() + STAY_UP
        seen: list[str] = []
        while time.monotonic() < deadline:
            now = state(name)
            assert now["Running"] and now["StartedAt"] == started and now["RestartCount"] == 0
            status = (now.get("Health") or {}).get("Status")
            assert status != "unhealthy", health(name)
            seen.append(str(status))
            time.sleep(10)
        final = health(name)
        assert final["Status"] == "healthy" and final["FailingStreak"] == 0
        assert all(entry["ExitCode"] == 0 for entry in final["Log"])
        assert '"buses_down": ["unplugged"]' in final["Log"][-1]["Output"]
        detail = docker(
            "exec", name, "python", "-c",
            "import urllib.request, urllib.error\ntry:\n urllib.request.urlopen("
            "'http://127.0.0.1:9464/health/buses')\nexcept urllib.error.HTTPError as e:\n"
            " print(e.code, e.read().decode())",
        ).stdout  # fmt: skip
        assert detail.startswith("503 ") and "unplugged" in detail
        logs = docker("logs", name)
        assert "(from the Supervisor)" in logs.stdout
        assert first_message(broker, "modbus/drive/availability", 10, login=login) == b"offline"
    finally:
        docker("rm", "-f", "-v", name, check=False)


def test_with_mqtt_url_the_addon_uses_that_broker(
    hassio: str, addon_image: str, tmp_path: Path
) -> None:
    """mqtt_url names another broker: discovery and state go there, not to the
    Supervisor's core-mosquitto."""
    settings = options(mqtt_url=f"mqtt://{OTHER_BROKER}:1883", base_topic="elsewhere")
    name = start_addon(hassio, addon_image, tmp_path, settings)
    try:
        other = core(OTHER_BROKER)
        assert first_message(other, "elsewhere/pump/availability", 60) == b"online"
        assert json.loads(first_message(other, "homeassistant/device/pump/config", 20))
        logs = docker("logs", name).stdout
        assert f"broker mqtt://{OTHER_BROKER}:1883 (from the add-on's options)" in logs
        with pytest.raises(queue.Empty):  # nothing on the Supervisor's broker
            first_message(core(CORE_MOSQUITTO), "elsewhere/bridge/state", 5,
                          login=(BROKER_USER, BROKER_PASSWORD))  # fmt: skip
    finally:
        docker("rm", "-f", "-v", name, check=False)
