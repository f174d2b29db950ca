"""The container files: docker-compose.yml, Dockerfile, .dockerignore and deploy/.

The compose file is checked as data (services, profiles, mounts), the configs it mounts
with the real config loader, the simulator command line with the real CLI parser, and,
where a compose binary is installed, with ``docker compose config`` itself.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
import yaml

from bridge.cli import _parser
from bridge.config import LoadedConfig, MetricsConfig, SerialBus, TcpBus, load_config
from bridge.core.mapping import builtin_mapping_names
from bridge.simulate_cli import build_simulator

ROOT = Path(__file__).resolve().parent.parent
COMPOSE_FILE = ROOT / "docker-compose.yml"
DOCKERFILE = ROOT / "Dockerfile"
CONFIG_TARGET = "/config/config.yaml"
BRIDGES = ("bridge", "bridge-demo")


def _compose() -> dict[str, Any]:
    return yaml.safe_load(COMPOSE_FILE.read_text(encoding="utf-8"))


def _services() -> dict[str, dict[str, Any]]:
    return _compose()["services"]


def _active(profile: str | None) -> set[str]:
    """Services `docker compose [--profile P] up` starts: no profile, or that profile."""
    return {
        name
        for name, service in _services().items()
        if not service.get("profiles") or profile in service["profiles"]
    }


def _mounted_config(service: dict[str, Any]) -> Path:
    """The repository file a service mounts read-only at /config/config.yaml."""
    mounts = [v.split(":") for v in service["volumes"] if v.split(":")[1] == CONFIG_TARGET]
    assert len(mounts) == 1, service["volumes"]
    source, _, mode = mounts[0]
    assert mode == "ro"
    return (ROOT / source).resolve()


def _loaded(service: str) -> LoadedConfig:
    return load_config(_mounted_config(_services()[service]))


def _simulate_args() -> Any:
    command = _services()["simulator"]["command"]
    assert all(isinstance(arg, str) for arg in command)
    return _parser().parse_args(command)


# --- docker-compose.yml -------------------------------------------------------------------


def test_services_and_profiles() -> None:
    services = _services()
    assert set(services) == {"mosquitto", "bridge", "simulator", "bridge-demo"}
    assert services["mosquitto"]["image"] == "eclipse-mosquitto:2"
    assert services["bridge"]["profiles"] == ["hardware"]
    assert services["simulator"]["profiles"] == ["demo"]
    assert services["bridge-demo"]["profiles"] == ["demo"]
    # A plain `up` starts the broker only; each profile adds its own bridge, never both.
    assert _active(None) == {"mosquitto"}
    assert _active("demo") == {"mosquitto", "simulator", "bridge-demo"}
    assert _active("hardware") == {"mosquitto", "bridge"}
    # The demo never asks for a serial device, so it starts on any machine.
    assert all("devices" not in services[name] for name in _active("demo"))
    for name, service in services.items():
        assert service["restart"] == "unless-stopped", name


def test_bridge_services_build_this_repository() -> None:
    services = _services()
    images = {services[name]["image"] for name in ("bridge", "simulator", "bridge-demo")}
    assert len(images) == 1  # one image, built once, for the three
    for name in ("bridge", "simulator", "bridge-demo"):
        assert services[name]["build"] == ".", name
    assert services["bridge"]["depends_on"] == {"mosquitto": {"condition": "service_healthy"}}
    assert services["bridge-demo"]["depends_on"] == {
        "mosquitto": {"condition": "service_healthy"},
        "simulator": {"condition": "service_healthy"},
    }


def test_mosquitto_config_is_mounted_and_listens_with_persistence() -> None:
    mosquitto = _services()["mosquitto"]
    [conf_mount] = [v for v in mosquitto["volumes"] if v.endswith("mosquitto.conf:ro")]
    source, target, _ = conf_mount.split(":")
    assert target == "/mosquitto/config/mosquitto.conf"
    lines = {
        line.strip()
        for line in (ROOT / source).read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    }
    assert {"listener 1883", "persistence true", "persistence_location /mosquitto/data/"} <= lines
    assert "mosquitto-data:/mosquitto/data" in mosquitto["volumes"]
    assert "mosquitto-data" in _compose()["volumes"]
    assert any(port.endswith(":1883") for port in mosquitto["ports"])


@pytest.mark.parametrize("service", BRIDGES)
def test_mounted_configs_exist_load_and_use_the_broker_service(service: str) -> None:
    path = _mounted_config(_services()[service])
    assert path.is_relative_to(ROOT / "deploy"), path
    config = _loaded(service).config
    url = urlsplit(config.mqtt.url)
    assert (url.hostname, url.port or 1883) == ("mosquitto", 1883)
    # The image's HEALTHCHECK fetches /metrics: both bridges must serve it.
    assert config.bridge.metrics.enabled
    assert config.bridge.metrics.host == "0.0.0.0"
    assert "healthcheck" not in _services()[service]  # the image's own check applies


def test_hardware_bridge_opens_the_passed_through_serial_device() -> None:
    bridge = _services()["bridge"]
    assert bridge["devices"] == ["/dev/ttyUSB0:/dev/ttyUSB0"]
    assert bridge["group_add"] == ["dialout"]
    in_container = {entry.split(":")[1] for entry in bridge["devices"]}
    serial = [bus for bus in _loaded("bridge").config.buses if isinstance(bus, SerialBus)]
    assert serial
    assert {bus.port for bus in serial} <= in_container


def test_demo_simulator_command_parses_with_the_real_cli() -> None:
    args = _simulate_args()
    assert args.command == "simulate"
    assert args.tcp == "0.0.0.0:5020"
    assert sorted(args.mapping) == sorted(builtin_mapping_names())  # all five seeds
    assert args.unit == [1, 2, 3, 4, 5]
    build_simulator(args)  # mappings load, units are unique, options are valid


def test_demo_bridge_polls_exactly_what_the_simulator_serves() -> None:
    args = _simulate_args()
    served = set(zip(args.mapping, args.unit, strict=True))
    loaded = _loaded("bridge-demo")
    [bus] = loaded.config.buses
    assert isinstance(bus, TcpBus)
    assert bus.transport == "tcp"  # the simulator's default framer on TCP is "socket"
    assert (bus.host, bus.tcp_port) == ("simulator", int(args.tcp.rpartition(":")[2]))
    polled = {(device.mapping, device.unit) for device in loaded.config.devices}
    assert polled == served
    # The same device ids as examples/config.yaml: the HA dashboard and Node-RED flow fit.
    example = load_config(ROOT / "examples" / "config.yaml").config
    assert [d.id for d in loaded.config.devices] == [d.id for d in example.devices]


def test_compose_healthcheck_commands_are_valid_python() -> None:
    test = _services()["simulator"]["healthcheck"]["test"]
    assert test[:3] == ["CMD", "python", "-c"]
    compile(test[3], "simulator healthcheck", "exec")
    assert "5020" in test[3]


def _compose_command() -> list[str] | None:
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    if shutil.which("docker"):
        probe = subprocess.run(
            ["docker", "compose", "version"], capture_output=True, timeout=30, check=False
        )
        if probe.returncode == 0:
            return ["docker", "compose"]
    return None


@pytest.mark.parametrize("profile", [None, "demo", "hardware"])
def test_docker_compose_config_accepts_the_file(profile: str | None) -> None:
    command = _compose_command()
    if command is None:
        pytest.skip("neither docker-compose nor the docker compose plugin is installed")
    selection = ["--profile", profile] if profile else []
    result = subprocess.run(
        [*command, "-f", str(COMPOSE_FILE), *selection, "config", "-q"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr


# --- Dockerfile -----------------------------------------------------------------------------


def _instructions() -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) in order, continuation lines joined, comments dropped."""
    joined = re.sub(r"\\\n", " ", DOCKERFILE.read_text(encoding="utf-8"))
    rows = []
    for line in joined.splitlines():
        text = line.strip()
        if text and not text.startswith("#"):
            instruction, _, arguments = text.partition(" ")
            rows.append((instruction.upper(), arguments.strip()))
    return rows


def _stages() -> list[list[tuple[str, str]]]:
    stages: list[list[tuple[str, str]]] = []
    for row in _instructions():
        if row[0] == "FROM":
            stages.append([])
        if stages:
            stages[-1].append(row)
    return stages


def _one(stage: list[tuple[str, str]], instruction: str) -> str:
    [arguments] = [args for name, args in stage if name == instruction]
    return arguments


def test_dockerfile_is_a_slim_two_stage_build() -> None:
    args = dict(arguments.split("=", 1) for name, arguments in _instructions() if name == "ARG")
    assert args["PYTHON_IMAGE"] == "python:3.11-slim"
    build, runtime = _stages()
    assert _one(build, "FROM") == "${PYTHON_IMAGE} AS build"
    assert _one(runtime, "FROM") == "${PYTHON_IMAGE} AS runtime"
    build_steps = _one(build, "RUN")
    assert "pip wheel" in build_steps
    assert "--no-index --find-links=/wheels modbus-mqtt-bridge" in build_steps
    # The runtime stage installs nothing: it copies the venv of wheels, no tools.
    runtime_text = " ".join(arguments for _, arguments in runtime)
    for tool in ("apt-get", "pip ", "gcc", "build-essential", "/wheels"):
        assert tool not in runtime_text, tool
    assert _one(runtime, "COPY") == "--from=build /opt/venv /opt/venv"


def test_dockerfile_runtime_user_entrypoint_volume_labels() -> None:
    runtime = _stages()[-1]
    user = _one(runtime, "USER")
    assert user.isdigit() and int(user) != 0  # numeric: runAsNonRoot can check it
    useradd = _one(runtime, "RUN")
    assert f"--uid {user} " in useradd
    assert "--groups dialout" in useradd  # serial devices
    assert _one(runtime, "ENTRYPOINT") == '["modbus-mqtt-bridge"]'
    assert _one(runtime, "CMD") == f'["run", "-c", "{CONFIG_TARGET}"]'
    assert _one(runtime, "VOLUME") == '["/config"]'
    labels = _one(runtime, "LABEL")
    for key in ("title", "description", "version", "licenses", "source"):
        assert f"org.opencontainers.image.{key}=" in labels, key
    assert 'licenses="MIT"' in labels


def test_dockerfile_healthcheck_fetches_the_default_metrics_endpoint() -> None:
    runtime = _stages()[-1]
    check = _one(runtime, "HEALTHCHECK")
    options, _, command = check.partition(" CMD ")
    assert "--interval=" in options and "--timeout=" in options
    python, flag, code = json.loads(command)  # the exec form is a JSON list
    assert (python, flag) == ("python", "-c")
    compile(code, "HEALTHCHECK", "exec")
    assert "urllib.request.urlopen(os.environ['BRIDGE_HEALTH_URL']" in code
    env = _one(runtime, "ENV")
    url = urlsplit(re.search(r"BRIDGE_HEALTH_URL=(\S+)", env).group(1))
    assert (url.hostname, url.port, url.path) == ("127.0.0.1", MetricsConfig().port, "/metrics")
    assert f"EXPOSE {MetricsConfig().port}" in {f"{n} {a}" for n, a in runtime}


def test_dockerignore_lets_through_exactly_what_the_build_copies() -> None:
    patterns = [
        line.strip()
        for line in (ROOT / ".dockerignore").read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.startswith("#")
    ]
    assert patterns[0] == "*"  # an allow-list: nothing by default
    allowed = {p[1:].rstrip("/") for p in patterns if p.startswith("!")}
    copied = set()
    for name, arguments in _stages()[0]:
        if name == "COPY":
            *sources, _ = arguments.split()
            copied |= {s.rstrip("/") for s in sources}
    assert copied == allowed
    for source in copied:
        assert (ROOT / source).exists(), source
