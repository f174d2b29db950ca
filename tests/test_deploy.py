"""The container files: docker-compose.yml, Dockerfile, .dockerignore and deploy/.

The compose file is checked as data (services, profiles, mounts), the configs it mounts
with the real config loader, the simulator command line with the real CLI parser, and,
where a compose binary is installed, with ``docker compose config`` itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
import yaml

from bridge.cli.console import _parser
from bridge.cli.simulate import build_simulator
from bridge.config import (
    LoadedConfig,
    MetricsConfig,
    SerialBus,
    TcpBus,
    WebConfig,
    load_config,
    load_config_data,
)
from bridge.core.health_report import BusSnapshot, Snapshot
from bridge.core.mapping import library_index, mappings_folder
from bridge.metrics import BUS_HEALTH_PATH, HEALTH_PATH, serve_metrics
from tests.ports import free_port

ROOT = Path(__file__).resolve().parent.parent
COMPOSE_FILE = ROOT / "docker-compose.yml"
DOCKERFILE = ROOT / "Dockerfile"
CONFIG_TARGET = "/config/config.yaml"
CONFIG_FOLDER = "/config"
COMPOSE_SETTINGS = ("MQTT_PORT", "MQTT_BIND", "SERIAL_GID", "SERIAL_PORT")
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
    """The repository file a service sees at /config/config.yaml: mounted read-only as
    that file, or as config.yaml of a folder mounted read-only at /config."""
    mounts = [v.split(":") for v in service["volumes"]]
    files = [(source, mode) for source, target, mode in mounts if target == CONFIG_TARGET]
    folders = [(source, mode) for source, target, mode in mounts if target == CONFIG_FOLDER]
    assert len(files) + len(folders) == 1, service["volumes"]
    source, mode = (files or folders)[0]
    assert mode == "ro"
    path = (ROOT / source).resolve()
    return path if files else path / "config.yaml"


def _loaded(service: str) -> LoadedConfig:
    return load_config(_mounted_config(_services()[service]))


def _simulate_args() -> Any:
    command = _services()["simulator"]["command"]
    assert all(isinstance(arg, str) for arg in command)
    return _parser().parse_args(command)


# --- docker-compose.yml -------------------------------------------------------------------


def test_services_and_profiles() -> None:
    services = _services()
    assert set(services) == {"mosquitto", "bridge", "simulator", "bridge-demo", "check"}
    assert services["mosquitto"]["image"] == "eclipse-mosquitto:2"
    assert services["bridge"]["profiles"] == ["hardware"]
    assert services["simulator"]["profiles"] == ["demo"]
    assert services["bridge-demo"]["profiles"] == ["demo"]
    assert services["check"]["profiles"] == ["tools"]  # only by name: `run --rm check`
    # A plain `up` starts the broker only; each profile adds its own bridge, never both.
    assert _active(None) == {"mosquitto"}
    assert _active("demo") == {"mosquitto", "simulator", "bridge-demo"}
    assert _active("hardware") == {"mosquitto", "bridge"}
    # The demo never asks for a serial device, so it starts on any machine.
    assert all("devices" not in services[name] for name in _active("demo"))
    for name, service in services.items():
        assert service["restart"] == ("no" if name == "check" else "unless-stopped"), name


def test_bridge_services_build_this_repository() -> None:
    services = _services()
    built = ("bridge", "simulator", "bridge-demo", "check")
    images = {services[name]["image"] for name in built}
    assert len(images) == 1  # one image, built once, for all of them
    for name in built:
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
    # The host side is configurable (another broker may hold 1883), loopback by default.
    assert mosquitto["ports"] == ["${MQTT_BIND:-127.0.0.1}:${MQTT_PORT:-1883}:1883"]


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
    assert bridge["devices"] == ["${SERIAL_PORT:-/dev/ttyUSB0}:/dev/ttyUSB0"]
    assert bridge["group_add"] == ["${SERIAL_GID:-dialout}"]  # the host's gid if not 20
    in_container = {entry.rsplit(":", 1)[1] for entry in bridge["devices"]}
    serial = [bus for bus in _loaded("bridge").config.buses if isinstance(bus, SerialBus)]
    assert serial
    assert {bus.port for bus in serial} <= in_container


def test_demo_simulator_command_parses_with_the_real_cli() -> None:
    args = _simulate_args()
    assert args.command == "simulate"
    assert args.tcp == "0.0.0.0:5020"
    seeds = [n for n, path in library_index().items() if path.parent == mappings_folder()]
    assert sorted(args.mapping) == sorted(seeds)  # all five seeds (not the device library)
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


def test_check_service_needs_no_adapter_no_broker_no_network() -> None:
    """`docker compose run --rm check` works before the adapter is plugged in: it opens
    no device, waits for no broker, and checks the file the hardware bridge runs."""
    services = _services()
    check = services["check"]
    for key in ("devices", "depends_on", "ports", "group_add"):
        assert key not in check, key
    assert check["network_mode"] == "none"
    assert check["healthcheck"] == {"disable": True}  # no metrics: it exits at once
    assert check["volumes"] == services["bridge"]["volumes"]
    assert _mounted_config(check) == ROOT / "deploy" / "config.yaml"
    args = _parser().parse_args(check["command"])
    assert (args.command, str(args.config)) == ("check", CONFIG_TARGET)


def test_check_service_runs_the_real_check_on_the_mounted_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """What the check service prints for deploy/config.yaml, from this checkout: the
    config and the mapping files it names load as the bridge would load them."""
    from bridge.cli import main  # noqa: PLC0415

    command = list(_services()["check"]["command"])
    config = _mounted_config(_services()["check"])
    command[command.index(CONFIG_TARGET)] = str(config)
    assert main(command) == 0
    assert f"{config}: ok (1 bus(es), 1 device(s)" in capsys.readouterr().out


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


def _published(port: Any) -> tuple[str, str, str]:
    """(host ip, host port, container port) of a port as `compose config` prints it:
    compose v1 keeps the short form, v2 the long one."""
    if isinstance(port, dict):
        return port.get("host_ip", ""), str(port["published"]), str(port["target"])
    host_ip, published, target = str(port).split("/")[0].rsplit(":", 2)
    return host_ip, published, target


@pytest.mark.parametrize(
    ("environment", "expected"),
    [
        ({}, ("127.0.0.1", "1883", "1883", "dialout", "/dev/ttyUSB0:/dev/ttyUSB0")),
        (
            {
                "MQTT_PORT": "22884",
                "MQTT_BIND": "0.0.0.0",
                "SERIAL_GID": "986",
                "SERIAL_PORT": "/dev/serial/by-id/usb-FTDI-if00-port0",
            },
            (
                "0.0.0.0",
                "22884",
                "1883",
                "986",
                "/dev/serial/by-id/usb-FTDI-if00-port0:/dev/ttyUSB0",
            ),
        ),
    ],
    ids=["defaults", "from-the-environment"],
)
def test_broker_port_and_serial_group_come_from_the_environment(
    environment: dict[str, str], expected: tuple[str, ...]
) -> None:
    """Another broker may hold 1883 on the host, the host's dialout may not be gid 20, the
    adapter has a stable by-id name: MQTT_PORT, MQTT_BIND, SERIAL_GID and SERIAL_PORT
    (environment or .env) change them, as compose itself resolves the file."""
    command = _compose_command()
    if command is None:
        pytest.skip("neither docker-compose nor the docker compose plugin is installed")
    clean = {k: v for k, v in os.environ.items() if k not in COMPOSE_SETTINGS}
    result = subprocess.run(
        [*command, "-f", str(COMPOSE_FILE), "--profile", "hardware", "config"],
        capture_output=True, text=True, timeout=60, check=False, cwd=ROOT,
        env=clean | environment,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    resolved = yaml.safe_load(result.stdout)["services"]
    [port] = resolved["mosquitto"]["ports"]
    [device] = resolved["bridge"]["devices"]
    device = device if isinstance(device, str) else f"{device['source']}:{device['target']}"
    group = str(resolved["bridge"]["group_add"][0])
    assert (*_published(port), group, device.removesuffix(":rwm")) == expected


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


def _args(stage: list[tuple[str, str]]) -> dict[str, str | None]:
    """The ARG lines of a stage (or of the lines before the first FROM): name -> default."""
    pairs = (arguments.partition("=") for name, arguments in stage if name == "ARG")
    return {name: value if sep else None for name, sep, value in pairs}


def _global_args() -> dict[str, str | None]:
    rows = _instructions()
    first_from = next(i for i, (name, _) in enumerate(rows) if name == "FROM")
    return _args(rows[:first_from])


def _header() -> str:
    """The comment block at the top of the Dockerfile, as one text (continuations joined)."""
    lines = []
    for line in DOCKERFILE.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.removeprefix("#").strip())
    return re.sub(r"\\\n\s*", " ", "\n".join(lines))


def header_commands() -> list[list[str]]:
    """Every `docker run ...` of the header, split as the shell would split it."""
    return [
        shlex.split(line.strip())
        for line in _header().splitlines()
        if line.strip().startswith("docker run ")
    ]


def test_dockerfile_is_a_slim_two_stage_build() -> None:
    assert _global_args()["PYTHON_IMAGE"] == "python:3.11-slim"
    build, runtime = _stages()
    assert _one(build, "FROM") == "${PYTHON_IMAGE} AS build"
    assert _one(runtime, "FROM") == "${PYTHON_IMAGE} AS runtime"
    build_steps = _one(build, "RUN")
    assert "pip wheel" in build_steps
    assert "--no-index --find-links=/wheels modbus-mqtt-bridge" in build_steps
    # The venv the runtime gets has no pip or setuptools: the base image's pip fills it.
    assert "python -m venv --without-pip /opt/venv" in build_steps
    assert "pip --python /opt/venv/bin/python install" in build_steps
    # The runtime stage installs nothing: it copies the venv of wheels, no tools.
    runtime_text = " ".join(arguments for _, arguments in runtime)
    for tool in ("apt-get", "pip ", "gcc", "build-essential", "/wheels"):
        assert tool not in runtime_text, tool
    assert _one(runtime, "COPY") == "--from=build /opt/venv /opt/venv"


def test_dockerfile_runtime_user_entrypoint_labels_and_no_volume() -> None:
    runtime = _stages()[-1]
    user = _one(runtime, "USER")
    assert user.isdigit() and int(user) != 0  # numeric: runAsNonRoot can check it
    useradd = _one(runtime, "RUN")
    assert f"--uid {user} " in useradd
    assert "--groups dialout" in useradd  # serial devices
    assert _one(runtime, "ENTRYPOINT") == '["modbus-mqtt-bridge"]'
    assert _one(runtime, "CMD") == f'["run", "-c", "{CONFIG_TARGET}"]'
    assert _one(runtime, "WORKDIR") == CONFIG_FOLDER
    # The config is a bind mount: a VOLUME would leave an anonymous volume per container.
    assert "VOLUME" not in {name for name, _ in _instructions()}
    labels = _one(runtime, "LABEL")
    for key in ("title", "description", "version", "licenses", "source"):
        assert f"org.opencontainers.image.{key}=" in labels, key
    assert 'licenses="MIT"' in labels


def test_dockerfile_labels_follow_the_build_args_and_the_package_version() -> None:
    runtime = _stages()[-1]
    labels = _one(runtime, "LABEL")
    args = _args(runtime)
    # The base image label is the PYTHON_IMAGE the image was built from.
    assert 'org.opencontainers.image.base.name="${PYTHON_IMAGE}"' in labels
    assert "PYTHON_IMAGE" in args and args["PYTHON_IMAGE"] is None  # the global default
    assert 'org.opencontainers.image.version="${VERSION}"' in labels
    # no copy of the version here: the release passes bridge.__version__, its one place
    assert "VERSION" in args and args["VERSION"] is None
    release = (ROOT / ".ci" / "release").read_text(encoding="utf-8")
    assert release.count('--build-arg "VERSION=$v"') == 2  # buildx and the classic builder
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert project["project"]["dynamic"] == ["version"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "bridge.__version__"}


def test_dockerfile_healthcheck_asks_the_bridge_whether_it_is_alive() -> None:
    runtime = _stages()[-1]
    check = _one(runtime, "HEALTHCHECK")
    options, _, command = check.partition(" CMD ")
    assert "--interval=" in options and "--timeout=" in options
    python, flag, code = json.loads(command)  # the exec form is a JSON list
    assert (python, flag) == ("python", "-c")
    compile(code, "HEALTHCHECK", "exec")
    env = _one(runtime, "ENV")
    url = urlsplit(re.search(r"BRIDGE_HEALTH_URL=(\S+)", env).group(1))
    assert (url.hostname, url.port, url.path) == ("127.0.0.1", MetricsConfig().port, HEALTH_PATH)
    exposed = {port for n, a in runtime if n == "EXPOSE" for port in a.split()}
    assert {str(MetricsConfig().port), str(WebConfig().port)} <= exposed


def healthcheck_code() -> str:
    command = _one(_stages()[-1], "HEALTHCHECK").partition(" CMD ")[2]
    return str(json.loads(command)[2])


def run_healthcheck(url: str) -> subprocess.CompletedProcess[str]:
    """The image's HEALTHCHECK command, as Docker runs it, against ``url``."""
    return subprocess.run(
        [sys.executable, "-c", healthcheck_code()],
        env={**os.environ, "BRIDGE_HEALTH_URL": url},
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )


@pytest.mark.asyncio
async def test_healthcheck_says_alive_while_a_bus_is_down_and_fails_when_nothing_answers() -> None:
    """The HEALTHCHECK command against the bridge's real metrics server: exit 0 while the
    buses are up, exit 0 too while one is down (restarting the bridge brings no gateway
    back), naming it in its output; exit 1 when nothing answers (the bridge is gone).
    /health/buses keeps the detail: 503 with the reason while the bus is down."""
    reason = "rs485: cannot open /dev/ttyUSB0: Permission denied [EACCES] (...)"
    up = BusSnapshot("rs485", "rtu", connected=True)
    down = BusSnapshot("rs485", "rtu", connected=False, down_reason=reason)
    current = [up]

    def source() -> Snapshot:
        return Snapshot(wall=0.0, monotonic=0.0, uptime=1.0, buses=(current[0],))

    port = free_port()
    url = f"http://127.0.0.1:{port}{HEALTH_PATH}"
    async with serve_metrics(MetricsConfig(enabled=True, port=port), source):
        healthy = await asyncio.to_thread(run_healthcheck, url)
        current[0] = down
        still = await asyncio.to_thread(run_healthcheck, url)
        detail = await asyncio.to_thread(
            run_healthcheck, f"http://127.0.0.1:{port}{BUS_HEALTH_PATH}"
        )
    gone = await asyncio.to_thread(run_healthcheck, url)
    assert (healthy.returncode, healthy.stderr) == (0, "")
    assert json.loads(healthy.stdout) == {"status": "ok"}
    assert (still.returncode, still.stderr) == (0, "")
    assert json.loads(still.stdout) == {"status": "ok", "buses_down": ["rs485"]}
    assert detail.returncode == 1
    assert json.loads(detail.stderr) == {"status": "down", "buses": {"rs485": reason}}
    assert gone.returncode == 1
    assert gone.stderr.startswith("no answer from the bridge:")


def test_header_examples_check_offline_and_run_against_a_reachable_broker() -> None:
    """The header's `docker run` lines: a check that needs no network and no adapter, and
    a run whose config (an example with mqtt://127.0.0.1) reaches a broker on the host,
    never deploy/config.yaml (its broker name resolves on the compose network only)."""
    header = _header()
    assert "deploy/config.yaml:" not in header
    check, run = header_commands()
    image = "modbus-mqtt-bridge"
    assert check[:3] == ["docker", "run", "--rm"]
    assert check[check.index("--network") + 1] == "none"
    assert "--device" not in check
    at = check.index(image)
    args = _parser().parse_args(check[at + 1 :])
    assert (args.command, str(args.config)) == ("check", CONFIG_TARGET)
    assert run[-1] == image  # the image's own CMD: run -c /config/config.yaml
    assert run[run.index("--network") + 1] == "host"
    assert run[run.index("--device") + 1] == "/dev/ttyUSB0"
    assert run[run.index("--group-add") + 1] == "$(stat -c %g /dev/ttyUSB0)"
    for command in (check, run):
        source, target, mode = command[command.index("-v") + 1].split(":")
        assert (source, target, mode) == ("$PWD/config.yaml", CONFIG_TARGET, "ro")
    # The configs the header points at use a broker on this host: --network host fits.
    for example in ("rtu-serial.yaml", "tcp.yaml"):
        assert f"examples/{example}" in header
        url = urlsplit(load_config(ROOT / "examples" / example).config.mqtt.url)
        assert url.hostname == "127.0.0.1"


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


# --- README: the container, Home Assistant and broker sections --------------------------------

README = (ROOT / "README.md").read_text(encoding="utf-8")


def readme_section(title: str) -> str:
    start = README.index(f"\n## {title}\n")
    end = README.find("\n## ", start + 1)
    return README[start : end if end > 0 else None]


def indented_blocks(text: str) -> list[str]:
    """The indented code blocks of a markdown text (in lists: 7 spaces), dedented."""
    blocks = re.findall(r"(?:\n\n)((?: {4,}\S.*\n?)+)", text)
    return [textwrap.dedent(block) for block in blocks]


def test_readme_compose_commands_name_real_services_profiles_and_settings() -> None:
    section = readme_section("Containers")
    services = _services()
    for command in re.findall(r"docker compose [^`\n)]*", section):
        words = command.split()
        for i, word in enumerate(words):
            if word == "--profile":
                assert any(words[i + 1] in s.get("profiles", []) for s in services.values())
        if "run" in words:
            assert words[words.index("run") + 2] in services, command  # run --rm SERVICE
        if "logs" in words or "-q" in words:
            assert words[-1] in services, command
    compose_text = COMPOSE_FILE.read_text(encoding="utf-8")
    for setting in set(re.findall(r"\b([A-Z][A-Z_]+)=", section)) - {"COMPOSE_PROFILES"}:
        assert "${" + setting + ":-" in compose_text, setting
    [env_file] = [b for b in indented_blocks(section) if "SERIAL_PORT=" in b]
    settings = dict(line.split("=", 1) for line in env_file.split())
    assert settings["COMPOSE_PROFILES"] in {
        p for s in services.values() for p in s.get("profiles", [])
    }


def test_readme_docker_run_lines_are_the_dockerfile_header_lines() -> None:
    section = re.sub(r"\\\n\s*", " ", readme_section("Containers"))
    commands = [shlex.split(line.strip()) for line in section.splitlines()
                if line.strip().startswith("docker run ")]  # fmt: skip
    assert commands == header_commands()


def _env_file_settings() -> dict[str, str]:
    [env_file] = [b for b in indented_blocks(readme_section("Containers")) if "SERIAL_PORT=" in b]
    return dict(line.split("=", 1) for line in env_file.split())


def test_readme_env_file_resolves_with_compose() -> None:
    command = _compose_command()
    if command is None:
        pytest.skip("neither docker-compose nor the docker compose plugin is installed")
    settings = _env_file_settings()
    clean = {k: v for k, v in os.environ.items() if k not in COMPOSE_SETTINGS}
    result = subprocess.run(
        [*command, "-f", str(COMPOSE_FILE), "config"],
        capture_output=True, text=True, timeout=60, check=False, cwd=ROOT, env=clean | settings,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    bridge = yaml.safe_load(result.stdout)["services"]["bridge"]  # the profile is on
    [device] = bridge["devices"]
    source = device if isinstance(device, str) else device["source"]
    assert str(source).startswith(settings["SERIAL_PORT"])


def test_readme_home_assistant_section_installs_the_addon_it_describes() -> None:
    from tests.supervisor_rules import SupervisorMissingError, option_problems  # noqa: PLC0415

    section = readme_section("Home Assistant add-on")
    addon = ROOT / "homeassistant-addon" / "modbus_mqtt_bridge"
    [url] = re.findall(r"`(https://github\.com/\S+#\S+)`", section)
    for document in (addon / "DOCS.md", ROOT / "homeassistant-addon" / "README.md"):
        assert url in document.read_text(encoding="utf-8"), document
    config = yaml.safe_load((addon / "config.yaml").read_text(encoding="utf-8"))
    assert url.partition("#")[0] == config["url"]
    [options_block] = [b for b in indented_blocks(section) if b.startswith("buses:")]
    options = yaml.safe_load(options_block)
    # without the Supervisor's code tests/test_addon.py says it is skipped; the rest holds
    with contextlib.suppress(SupervisorMissingError):
        assert option_problems(options, config["schema"]) == []
    # ... and the bridge takes what the add-on makes of them
    spec = importlib.util.spec_from_file_location("addon_run", addon / "run.py")
    assert spec is not None and spec.loader is not None
    run = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(run)
    service = {"host": "core-mosquitto", "port": 1883, "username": "addons"}
    data, base = run.bridge_config(options, service)
    loaded = load_config_data(data, base / "config.yaml").config
    assert [d.mapping for d in loaded.devices] == ["nastec_vasco"]
    for link in re.findall(r"\]\(([^)]+)\)", section):
        assert (ROOT / link).exists(), link


def test_readme_broker_section_links_the_table() -> None:
    section = readme_section("MQTT brokers")
    assert "(docs/brokers.md)" in section
    table = (ROOT / "docs" / "brokers.md").read_text(encoding="utf-8")
    for broker in ("Mosquitto", "NATS", "RabbitMQ", "amqtt"):
        assert broker in section and broker in table
