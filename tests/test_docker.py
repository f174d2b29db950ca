"""The container image, built and run for real (skipped when no Docker engine answers).

The image is built once per session from this checkout (``docker build --network host``:
the build reaches PyPI the way the host does) and tagged ``modbus-mqtt-bridge:pytest``.
The engine is the one ``DOCKER_HOST`` names, else the default socket. Nothing here
publishes a port: the bridges in these tests run with ``--network host`` (a private
Mosquitto on a free loopback port) or ``--network none``.

    DOCKER_HOST=unix:///tmp/dk-docker/docker.sock .venv/bin/pytest tests/test_docker.py
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import pytest
import yaml

from bridge import __version__
from bridge.core.mapping import builtin_mapping_names
from tests.integration.mosquitto import Broker
from tests.ports import free_port
from tests.test_deploy import header_commands

ROOT = Path(__file__).resolve().parent.parent
IMAGE = "modbus-mqtt-bridge:pytest"
BUILD_TIMEOUT = 900  # a cold build downloads every wheel
pytestmark = pytest.mark.timeout(BUILD_TIMEOUT + 120)


def docker(
    *args: str, timeout: float = 120, check: bool = True
) -> subprocess.CompletedProcess[str]:
    result = subprocess.run(
        ["docker", *args], capture_output=True, text=True, timeout=timeout, check=False
    )
    if check and result.returncode != 0:
        raise AssertionError(f"docker {' '.join(args)}: {result.returncode}\n{result.stderr}")
    return result


def _engine_answers() -> bool:
    if shutil.which("docker") is None:
        return False
    try:
        return (
            docker("info", "--format", "{{.ServerVersion}}", timeout=20, check=False).returncode
            == 0
        )
    except subprocess.TimeoutExpired:
        return False


@pytest.fixture(scope="session")
def image() -> str:
    if not _engine_answers():
        pytest.skip("no Docker engine answers (set DOCKER_HOST, or start dockerd)")
    docker(
        "build", "--network", "host", "--build-arg", f"VERSION={__version__}", "-t", IMAGE,
        str(ROOT), timeout=BUILD_TIMEOUT,
    )  # fmt: skip
    return IMAGE


def run(image: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """``docker run --rm --network none IMAGE ARGS``: the bridge's CLI in the image."""
    return docker("run", "--rm", "--network", "none", *args, timeout=timeout, check=False)


def test_help_and_version(image: str) -> None:
    helped = run(image, image, "--help")
    assert helped.returncode == 0, helped.stderr
    assert helped.stdout.startswith("usage: modbus-mqtt-bridge")
    version = run(image, image, "--version")
    assert version.stdout.strip() == f"modbus-mqtt-bridge {__version__}"


def test_mappings_list_has_every_shipped_mapping(image: str) -> None:
    listed = run(image, image, "mappings", "list")
    assert listed.returncode == 0, listed.stderr
    names = [line.split()[0] for line in listed.stdout.splitlines()[1:]]
    assert names == builtin_mapping_names()


@pytest.mark.parametrize(
    ("mount", "expected"),
    [
        # as the compose `check` and `bridge` services mount it: the whole deploy folder
        (f"{ROOT / 'deploy'}:/config:ro", "(1 bus(es), 1 device(s)"),
        (f"{ROOT / 'deploy' / 'demo.yaml'}:/config/config.yaml:ro", "(1 bus(es), 5 device(s)"),
    ],
    ids=["config.yaml", "demo.yaml"],
)
def test_check_on_the_deploy_configs_without_adapter_or_network(
    image: str, mount: str, expected: str
) -> None:
    checked = run(image, "-v", mount, image, "check", "-c", "/config/config.yaml")
    assert checked.returncode == 0, checked.stderr
    assert checked.stdout.startswith(f"/config/config.yaml: ok {expected}")


def test_check_of_a_bad_config_names_the_field(image: str, tmp_path: Path) -> None:
    config = yaml.safe_load((ROOT / "deploy" / "config.yaml").read_text(encoding="utf-8"))
    config["devices"][0]["unit"] = 0
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(config), encoding="utf-8")
    (tmp_path / "config.yaml").chmod(0o644)
    tmp_path.chmod(0o755)  # the image's user (uid 10001) reads the mounted folder
    checked = run(
        image, "-v", f"{tmp_path}:/config:ro", image, "check", "-c", "/config/config.yaml"
    )
    assert checked.returncode == 2
    assert "devices.borehole_pump.unit:" in checked.stderr


def test_the_dockerfile_header_check_runs_as_written(image: str, tmp_path: Path) -> None:
    """The header's check line, with $PWD a folder holding a copy of the example it
    recommends: exit 0, no network, no adapter."""
    check, _ = header_commands()
    shutil.copy(ROOT / "examples" / "rtu-serial.yaml", tmp_path / "config.yaml")
    (tmp_path / "config.yaml").chmod(0o644)
    command = [arg.replace("$PWD", str(tmp_path)) for arg in check]
    command[command.index("modbus-mqtt-bridge")] = image
    checked = docker(*command[1:], check=False)
    assert checked.returncode == 0, checked.stderr
    assert checked.stdout.startswith("/config/config.yaml: ok")


def test_the_image_holds_no_pip_no_volume_and_its_labels(image: str) -> None:
    probe = run(
        image,
        "--entrypoint",
        "python",
        image,
        "-c",
        "import importlib.util as u, sys; print(sys.prefix, "
        "[m for m in ('pip', 'setuptools', 'wheel') if u.find_spec(m)])",
    )
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.split(" ", 1) == ["/opt/venv", "[]\n"]
    who = run(image, "--entrypoint", "id", image)
    assert (
        who.stdout.strip() == "uid=10001(bridge) gid=10001(bridge) groups=10001(bridge),20(dialout)"
    )
    config = json.loads(docker("image", "inspect", "-f", "{{json .Config}}", image).stdout)
    assert not config.get("Volumes")  # no VOLUME: no anonymous volume per container
    assert config["User"] == "10001"
    labels = config["Labels"]
    assert labels["org.opencontainers.image.version"] == __version__
    assert labels["org.opencontainers.image.base.name"] == "python:3.11-slim"


def test_the_base_image_label_follows_the_build_argument(image: str) -> None:
    """Built FROM another tag of the base, the label says so (it used to be fixed)."""
    other = "modbus-mqtt-bridge-pytest-base:1"
    docker("tag", "python:3.11-slim", other)
    try:
        docker(
            "build", "--network", "host", "--build-arg", f"PYTHON_IMAGE={other}",
            "-t", f"{IMAGE}-base", str(ROOT), timeout=BUILD_TIMEOUT,
        )  # fmt: skip
        label = docker(
            "image", "inspect", "-f",
            '{{index .Config.Labels "org.opencontainers.image.base.name"}}', f"{IMAGE}-base",
        )  # fmt: skip
        assert label.stdout.strip() == other
    finally:
        docker("rmi", f"{IMAGE}-base", check=False)
        docker("rmi", other, check=False)


# --- a bridge in the image on a serial line -------------------------------------------------


@pytest.fixture
def serial_line(tmp_path: Path) -> Iterator[str]:
    """A simulated Nastec pump (unit 1) on one end of a virtual cable on this host; yields
    the other end, which a container opens as its /dev/ttyUSB0."""
    if os.geteuid() != 0:
        pytest.skip("giving the pty to another group needs root")
    log = (tmp_path / "simulator.log").open("w+")
    simulator = subprocess.Popen(
        [sys.executable, "-m", "bridge.cli", "simulate",
         "--mapping", "nastec_vasco", "--unit", "1", "--pty"],
        stdout=log, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        port = None
        deadline = time.monotonic() + 20
        while port is None and time.monotonic() < deadline:
            log.seek(0)
            found = re.search(r"open (/dev/pts/\d+) from the bridge", log.read())
            port = found.group(1) if found else None
            if port is None:
                assert simulator.poll() is None, "the simulator ended"
                time.sleep(0.1)
        assert port is not None, "the simulator printed no port"
        yield port
    finally:
        simulator.send_signal(signal.SIGTERM)
        simulator.wait(10)
        log.close()


def bridge_config(broker: Broker, metrics_port: int) -> dict[str, Any]:
    config = yaml.safe_load((ROOT / "deploy" / "config.yaml").read_text(encoding="utf-8"))
    config["mqtt"]["url"] = broker.url
    config["bridge"]["metrics"] = {"enabled": True, "host": "127.0.0.1", "port": metrics_port}
    config["bridge"]["health_interval"] = 1
    config["buses"][0]["timeout"] = "0.3s"
    config["devices"][0]["poll"] = {"fast": "1s", "slow": "10s"}
    return config


def health(container: str) -> dict[str, Any]:
    state = docker("inspect", "-f", "{{json .State.Health}}", container).stdout
    return json.loads(state) or {}


def wait_for_health(container: str, wanted: str, timeout: float = 45) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        current = health(container)
        if current.get("Status") == wanted:
            return current
        if time.monotonic() > deadline:
            logs = docker("logs", container, check=False)
            raise AssertionError(f"{container}: {current}\n{logs.stdout}{logs.stderr}")
        time.sleep(0.5)


@pytest.mark.parametrize("joined", [False, True], ids=["not-in-the-group", "group-add"])
def test_a_bridge_on_a_serial_port_of_another_group(
    image: str, serial_line: str, mosquitto: Broker, tmp_path: Path, joined: bool
) -> None:
    """The adapter belongs to a host group the image's user is not in (gid 4321, as on a
    host whose dialout is not 20): the container stays healthy (the bridge is alive; a
    restart would not fix the group), its health log names the bus down, and its log and
    /health/buses say why and what to pass (--group-add 4321). With --group-add 4321 it
    is healthy and publishes the pump's values."""
    gid = 4321
    os.chown(serial_line, 0, gid)
    os.chmod(serial_line, 0o660)
    metrics_port = free_port()
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(bridge_config(mosquitto, metrics_port)))
    (tmp_path / "config.yaml").chmod(0o644)
    name = f"pytest-bridge-{os.getpid()}-{int(joined)}"
    options = [
        "--name", name, "--network", "host",
        "--health-interval", "1s", "--health-start-period", "0s", "--health-retries", "1",
        "-e", f"BRIDGE_HEALTH_URL=http://127.0.0.1:{metrics_port}/health",
        "-v", f"{serial_line}:/dev/ttyUSB0", "-v", f"{tmp_path}/config.yaml:/config/config.yaml:ro",
    ]  # fmt: skip
    if joined:
        options += ["--group-add", str(gid)]
    docker("run", "-d", *options, image)
    try:
        if joined:
            wait_for_health(name, "healthy")
            assert first_message(mosquitto, "modbus/borehole_pump/availability") == b"online"
            return
        state = wait_for_bus_down(name)
        assert state["Status"] == "healthy"
        refused = bus_health(metrics_port)
        assert refused.code == 503
        reason = json.loads(refused.read())["buses"]["rs485"]
        assert "cannot open /dev/ttyUSB0: Permission denied [EACCES]" in reason
        assert f"group {gid} and uid 10001 is not in it" in reason
        assert f"--group-add {gid}" in reason
        logs = docker("logs", name).stderr
        assert f"--group-add {gid}" in logs
    finally:
        docker("rm", "-f", "-v", name, check=False)


def wait_for_bus_down(container: str, timeout: float = 45) -> dict[str, Any]:
    """The container's health once its check's output names a bus down."""
    deadline = time.monotonic() + timeout
    while True:
        current = health(container)
        log = current.get("Log") or [{}]
        if "buses_down" in str(log[-1].get("Output", "")):
            return current
        if time.monotonic() > deadline:
            raise AssertionError(f"{container}: no bus down in {current}")
        time.sleep(0.5)


def bus_health(port: int) -> urllib.error.HTTPError:
    """GET /health/buses on the host, expected to be refused (a bus is down)."""
    try:
        urllib.request.urlopen(f"http://127.0.0.1:{port}/health/buses", timeout=5)
    except urllib.error.HTTPError as refused:
        return refused
    raise AssertionError("/health/buses answered 200 with a bus down")


def first_message(
    broker: Broker, topic: str, timeout: float = 20, login: tuple[str, str] | None = None
) -> bytes:
    """The first (retained) message on ``topic``, read by a plain paho client."""
    received: queue.Queue[bytes] = queue.Queue()
    client = paho.Client(paho.CallbackAPIVersion.VERSION2)
    if login is not None:
        client.username_pw_set(*login)
    client.on_message = lambda _client, _userdata, message: received.put(message.payload)
    client.connect(broker.host, broker.port)
    client.subscribe(topic)
    client.loop_start()
    try:
        return received.get(timeout=timeout)
    finally:
        client.loop_stop()
        client.disconnect()


# --- docker compose --------------------------------------------------------------------------


def compose_command() -> list[str] | None:
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    if docker("compose", "version", check=False).returncode == 0:
        return ["docker", "compose"]
    return None


def test_compose_check_service_runs_without_the_adapter(image: str) -> None:
    """`docker compose run --rm check` on this checkout: no /dev/ttyUSB0 on this machine,
    no broker started, exit 0 with the check's line."""
    command = compose_command()
    if command is None:
        pytest.skip("no docker compose")
    if Path("/dev/ttyUSB0").exists():
        pytest.skip("this machine has a /dev/ttyUSB0: the test is about one without")
    docker("tag", image, "modbus-mqtt-bridge:local")  # the name the compose file builds
    project = f"pytest{os.getpid()}"
    try:
        checked = subprocess.run(
            [*command, "-p", project, "run", "--rm", "check"],
            cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
        assert checked.returncode == 0, checked.stderr
        assert "/config/config.yaml: ok (1 bus(es), 1 device(s)" in checked.stdout
        containers = docker("ps", "-a", "--filter", f"label=com.docker.compose.project={project}",
                            "--format", "{{.Names}}").stdout  # fmt: skip
        assert containers.strip() == ""  # no broker was started, the check was removed
    finally:
        subprocess.run([*command, "-p", project, "down", "-v"], cwd=ROOT, capture_output=True,
                       timeout=120, check=False)  # fmt: skip


# The Home Assistant add-on, built as the Supervisor builds it: tests/test_addon_docker.py.
