"""The Home Assistant add-on (homeassistant-addon/): its files against the Supervisor's
own rules (its code at a pinned release: tests/supervisor_rules.py), and its start script against a fake Supervisor HTTP API, a
real Mosquitto with a password and the simulator: the broker and credentials come from
the Supervisor's answer to ``GET /services/mqtt``, the buses and devices from the options,
and the bridge it starts publishes discovery and state.
"""

from __future__ import annotations

import asyncio
import importlib.metadata
import importlib.util
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar

import pytest
import yaml

from bridge import __version__
from bridge.config import MqttConfig, load_config_data
from bridge.config.edits import parse_change
from bridge.config.store import ConfigStore
from bridge.core.mapping import builtin_mapping_names
from bridge.errors import ConfigReadOnlyError
from bridge.mqtt import MqttClient
from tests.conftest import BROKER_PASSWORD, BROKER_USER
from tests.integration.harness import eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.ports import free_port
from tests.supervisor_rules import (
    SupervisorMissingError,
    config_problems,
    load,
    option_problems,
    translation_problems,
)

ROOT = Path(__file__).resolve().parent.parent
REPOSITORY = ROOT / "homeassistant-addon"
ADDON = REPOSITORY / "modbus_mqtt_bridge"
RUN = ADDON / "run.py"
TOKEN = "supervisor-token-for-the-test"


def _yaml(path: Path) -> Any:
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def addon_config() -> dict[str, Any]:
    config: dict[str, Any] = _yaml(ADDON / "config.yaml")
    return config


# --- the files ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def supervisor() -> None:
    """The Supervisor's rules are there (its source at the pinned commit), else skip."""
    try:
        load()
    except SupervisorMissingError as missing:
        pytest.skip(str(missing))


@pytest.mark.usefixtures("supervisor")
def test_config_follows_the_supervisor_rules() -> None:
    """No error and no advisory (deprecated or legacy keys) from the Supervisor itself."""
    assert config_problems(addon_config()) == []


@pytest.mark.usefixtures("supervisor")
def test_the_supervisor_refuses_what_the_old_hand_written_rules_let_through() -> None:
    """The checker is the Supervisor, not a rubber stamp: each broken rule is named."""
    broken = addon_config() | {
        "slug": "modbus bridge",
        "services": ["mqtt:needed"],
        "map": ["addon_config:ro"],
        "watchdog": "http://localhost:9464/health",
        "image": "ghcr.io/modbus mqtt bridge",
        "timeout": 5,
        "startup": "sometimes",
    }
    found = "\n".join(config_problems(broken))
    for expected in (
        "slug: does not match",
        "services.0: does not match",
        "watchdog: does not match",
        "image: Invalid Docker image",
        "timeout: value must be at least 10",
        "startup: expected AppStartup",
        "uses legacy map type 'addon_config'; use 'app_config' instead",
    ):
        assert expected in found, (expected, found)
    del broken["name"]
    assert config_problems(broken) == [": Invalid app config!"]


@pytest.mark.usefixtures("supervisor")
@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ({"log_level": "loud"}, "value must be one of ['debug', 'error', 'info', 'warning']"),
        ({"buses": [{"id": "RS 485", "transport": "rtu"}]}, "does not match regular expression"),
        ({"buses": [{"id": "rs485", "transport": "modbus"}]}, "value must be one of"),
        (
            {"buses": [{"id": "rs485", "transport": "rtu", "stopbits": 3}]},
            "value must be at most 2",
        ),
        ({"mqtt_url": "not a url"}, "expected a URL"),
        ({"level": "x"}, "Option 'level' does not exist in the schema"),
    ],
    ids=["enum", "match", "transport", "range", "url", "unknown"],
)
def test_the_supervisor_refuses_bad_options(change: dict[str, Any], expected: str) -> None:
    config = addon_config()
    found = "\n".join(option_problems(config["options"] | change, config["schema"]))
    assert expected in found, found


@pytest.mark.usefixtures("supervisor")
def test_translations_follow_the_supervisor_rules() -> None:
    assert translation_problems(_yaml(ADDON / "translations" / "en.yaml")) == []


def test_config_declares_what_the_issue_asks() -> None:
    config = addon_config()
    # the broker comes from the Supervisor if one is there, else from mqtt_url
    assert config["services"] == ["mqtt:want"]
    assert config["uart"] is True and "usb" not in config  # serial adapters, no raw USB
    assert sorted(config["arch"]) == ["aarch64", "amd64"]
    assert config["slug"] == ADDON.name
    assert config["map"] == ["app_config:ro", "share:ro"]
    assert "apparmor" not in config  # on by default, with the profile below
    assert (ADDON / "apparmor.txt").read_text(encoding="utf-8").count(
        f"profile {config['slug']} flags="
    ) == 1
    schema = config["schema"]
    assert set(schema) == {"buses", "devices", "config_file", "mqtt_url", "mqtt_username",
                           "mqtt_password", "base_topic", "discovery_prefix", "log_level"}  # fmt: skip
    assert (schema["mqtt_url"], schema["mqtt_username"], schema["mqtt_password"]) == (
        "url?", "str?", "password?"
    )  # fmt: skip
    assert not any(key.startswith("mqtt") for key in config["options"])  # Home Assistant's


def test_version_is_the_package_version_everywhere() -> None:
    version = importlib.metadata.version("modbus-mqtt-bridge")  # from bridge/__init__.py
    assert addon_config()["version"] == version == __version__
    dockerfile = (ADDON / "Dockerfile").read_text(encoding="utf-8")
    # the Supervisor passes config.yaml's version as BUILD_VERSION: the image of that tag
    assert re.findall(r"^(ARG|FROM) (.+)$", dockerfile, re.MULTILINE) == [
        ("ARG", "BUILD_VERSION"),
        ("FROM", "ghcr.io/modbus-mqtt-bridge/modbus-mqtt-bridge:${BUILD_VERSION}"),
    ]
    assert f"## {version}" in (ADDON / "CHANGELOG.md").read_text(encoding="utf-8")
    # BUILD_FROM is what older Supervisors fill with their own Alpine base: not used
    assert "BUILD_FROM" not in re.sub(r"#.*", "", dockerfile)
    assert not (ADDON / "build.yaml").exists()  # Supervisor 2026.04 dropped it


def test_dockerfile_runs_the_start_script_on_the_bridge_image() -> None:
    lines = [
        line.strip()
        for line in (ADDON / "Dockerfile").read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    ]
    assert "COPY run.py /opt/addon/run.py" in lines
    assert 'ENTRYPOINT ["python", "/opt/addon/run.py"]' in lines
    assert "USER root" in lines
    assert "HEALTHCHECK NONE" not in lines  # the image's health check stays


def test_translations_name_every_option() -> None:
    schema = addon_config()["schema"]
    translated = _yaml(ADDON / "translations" / "en.yaml")["configuration"]
    assert set(translated) == set(schema)
    for key, entry in translated.items():
        assert entry["name"] and entry["description"], key
        nested = schema[key][0] if isinstance(schema[key], list) else None
        if isinstance(nested, dict):
            assert set(entry["fields"]) == set(nested), key
            assert all(field["name"] for field in entry["fields"].values())


def test_the_folder_is_an_add_on_repository_root() -> None:
    """What the Supervisor does with a repository: repository.yaml at the root, and every
    config.json/yaml/yml below (outside dot folders and rootfs) taken for an add-on. Here
    that is exactly one, the add-on's."""
    candidates = [p.relative_to(REPOSITORY) for p in REPOSITORY.glob("**/config.*")]
    found = [
        path
        for path in candidates
        if path.suffix in (".json", ".yaml", ".yml")
        and not any(part.startswith(".") or part == "rootfs" for part in path.parts)
    ]
    assert found == [Path("modbus_mqtt_bridge/config.yaml")]
    assert (REPOSITORY / "repository.yaml").is_file()


def test_repository_and_store_files() -> None:
    repository = _yaml(REPOSITORY / "repository.yaml")
    assert set(repository) == {"name", "url", "maintainer"}
    assert repository["url"].startswith("https://github.com/")
    for name in ("DOCS.md", "README.md", "CHANGELOG.md"):
        assert (ADDON / name).read_text(encoding="utf-8").startswith("# "), name
    for name, size in (("icon.png", (128, 128)), ("logo.png", (250, 100))):
        data = (ADDON / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n", name
        width, height = int.from_bytes(data[16:20]), int.from_bytes(data[20:24])
        assert (width, height) == size, name


@pytest.mark.usefixtures("supervisor")
def test_default_options_and_docs_examples_fit_the_schema() -> None:
    config = addon_config()
    docs = re.findall(r"```yaml\n(.*?)```", (ADDON / "DOCS.md").read_text(encoding="utf-8"), re.S)
    assert len(docs) == 4
    for options in [config["options"], *(yaml.safe_load(block) for block in docs)]:
        assert option_problems(options, config["schema"]) == [], options


# --- the start script, imported -------------------------------------------------------------


@pytest.fixture(scope="module")
def run_module() -> ModuleType:
    spec = importlib.util.spec_from_file_location("addon_run", RUN)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SERVICE = {"host": "core-mosquitto", "port": 1883, "ssl": False, "protocol": "3.1.1",
           "username": "addons", "password": "s3cret", "addon": "core_mosquitto"}  # fmt: skip


@pytest.mark.parametrize("block", [0, 1], ids=["rtu", "tcp"])
def test_docs_examples_make_valid_bridge_configs(
    run_module: ModuleType, block: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    docs = re.findall(r"```yaml\n(.*?)```", (ADDON / "DOCS.md").read_text(encoding="utf-8"), re.S)
    data, base = run_module.bridge_config(yaml.safe_load(docs[block]), SERVICE)
    monkeypatch.setenv(run_module.PASSWORD_ENV, "s3cret")
    loaded = load_config_data(data, base / "config.yaml")
    mqtt = loaded.config.mqtt
    assert (mqtt.url, mqtt.username, mqtt.password_env) == (
        "mqtt://core-mosquitto:1883", "addons", run_module.PASSWORD_ENV
    )  # fmt: skip
    assert "s3cret" not in json.dumps(data)
    metrics = loaded.config.bridge.metrics
    assert (metrics.enabled, metrics.host, metrics.port) == (True, "127.0.0.1", 9464)
    web = loaded.config.bridge.web  # in the sidebar through ingress: the proxy alone gets in
    assert (web.enabled, web.port, web.token) == (True, addon_config()["ingress_port"], None)
    assert [str(address) for address in web.ingress_proxies] == ["172.30.32.2"]
    assert addon_config()["ingress"] is True


def test_a_config_file_keeps_its_settings_but_not_its_broker(
    run_module: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """config_file mode: the file's topics, device options and own mapping file (a path
    relative to the add-on's folder) are kept; its broker, user and TLS are the
    Supervisor's."""
    monkeypatch.setattr(run_module, "CONFIG_DIR", tmp_path)
    shutil.copy(ROOT / "examples" / "mappings" / "energy_meter.yaml", tmp_path / "meter.yaml")
    own = {
        "mqtt": {"url": "mqtts://elsewhere:8883", "username": "me", "password": "other",
                 "base_topic": "plant", "qos": 0, "tls": {"insecure": True}},
        "bridge": {"health_interval": "30s"},
        "buses": [{"id": "gw", "transport": "tcp", "host": "192.0.2.7"}],
        "devices": [
            {"id": "meter", "bus": "gw", "unit": 2, "mapping": "meter.yaml"},
            {"id": "pump", "bus": "gw", "unit": 1, "mapping": "nastec_vasco",
             "options": {"register_9f": "pcb_temperature"}},
        ],
    }  # fmt: skip
    (tmp_path / "bridge.yaml").write_text(yaml.safe_dump(own), encoding="utf-8")
    options = {"buses": [], "devices": [], "config_file": "bridge.yaml",
               "base_topic": "modbus", "discovery_prefix": "homeassistant", "log_level": "info"}  # fmt: skip
    data, base = run_module.bridge_config(options, SERVICE)
    monkeypatch.setenv(run_module.PASSWORD_ENV, "s3cret")
    config = load_config_data(data, base / "config.yaml").config
    assert config.mqtt.url == "mqtt://core-mosquitto:1883"
    assert (config.mqtt.username, config.mqtt.password, config.mqtt.tls) == ("addons", None, None)
    assert (config.mqtt.base_topic, config.mqtt.qos) == ("plant", 0)  # the file's
    assert config.mqtt.discovery_prefix == "homeassistant"  # the option, the file has none
    assert config.bridge.health_interval == 30
    assert config.devices[0].mapping == str(tmp_path / "meter.yaml")
    assert config.devices[1].mapping == "nastec_vasco"
    assert config.devices[1].options == {"register_9f": "pcb_temperature"}


def test_a_config_file_may_be_in_the_addons_folder_or_under_share(
    run_module: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A name relative to the add-on's folder, a full path under it or under /share, or a
    link that leads there; mapping paths are relative to the file's own folder."""
    config, share = tmp_path / "config", tmp_path / "share"
    (share / "modbus").mkdir(parents=True)
    config.mkdir()
    monkeypatch.setattr(run_module, "CONFIG_DIR", config)
    monkeypatch.setattr(run_module, "SHARE_DIR", share)
    own = {"buses": [{"id": "gw", "transport": "tcp", "host": "192.0.2.7"}],
           "devices": [{"id": "meter", "bus": "gw", "unit": 2, "mapping": "meter.yaml"}]}  # fmt: skip
    for folder in (config, share / "modbus"):
        (folder / "bridge.yaml").write_text(yaml.safe_dump(own), encoding="utf-8")
    (config / "shared.yaml").symlink_to(share / "modbus" / "bridge.yaml")
    for name, folder in [
        ("bridge.yaml", config),
        (str(config / "bridge.yaml"), config),
        ("sub/../bridge.yaml", config),
        (str(share / "modbus" / "bridge.yaml"), share / "modbus"),
        ("shared.yaml", share / "modbus"),
    ]:
        options = {"buses": [], "devices": [], "config_file": name}
        data, base = run_module.bridge_config(options, SERVICE)
        assert (base, data["devices"][0]["mapping"]) == (folder, str(folder / "meter.yaml")), name


def test_ssl_broker_is_reached_over_mqtts(run_module: ModuleType) -> None:
    service = SERVICE | {"ssl": True, "port": 8883}
    section = run_module.mqtt_section(service, {})
    assert section["url"] == "mqtts://core-mosquitto:8883"
    assert section["tls"] == {"insecure": True}  # the certificate names the public host


def test_buses_and_devices_in_both_places_are_refused(run_module: ModuleType) -> None:
    options = {"config_file": "bridge.yaml", "devices": [{"id": "x"}], "buses": []}
    with pytest.raises(run_module.AddonError, match="not both"):
        run_module.bridge_config(options, SERVICE)


# --- the start script against a fake Supervisor --------------------------------------------


class FakeSupervisor:
    """``GET /services/mqtt`` as the Supervisor answers it: 401 without the add-on's token,
    then ``answer`` (status, JSON body). Records the requests."""

    def __init__(self, answer: tuple[int, Any]) -> None:
        self.answer = answer
        self.requests: list[tuple[str, str | None]] = []
        fake = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"
            server_version: ClassVar[str] = "fake-supervisor"  # type: ignore[misc]

            def do_GET(self) -> None:
                fake.requests.append((self.path, self.headers.get("Authorization")))
                if self.headers.get("Authorization") != f"Bearer {TOKEN}":
                    status, body = 401, {"result": "error", "message": "Unauthorized"}
                elif self.path != "/services/mqtt":
                    status, body = 404, {"result": "error", "message": "Not found"}
                else:
                    status, body = fake.answer
                data = json.dumps(body).encode()
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def __enter__(self) -> FakeSupervisor:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()
        self.server.server_close()


def mqtt_answer(broker: Broker) -> tuple[int, dict[str, Any]]:
    data = {"host": broker.host, "port": broker.port, "ssl": False, "protocol": "3.1.1",
            "username": BROKER_USER, "password": BROKER_PASSWORD, "addon": "core_mosquitto"}  # fmt: skip
    return 200, {"result": "ok", "data": data}


NO_BROKER = (400, {"result": "error", "message": "Service not enabled"})
A_BROKER = (200, {"result": "ok", "data": SERVICE})  # nobody listens: for what fails before


@pytest.fixture
def addon_dirs(tmp_path: Path) -> dict[str, Path]:
    """/data, /config (the add-on's folder), /share and /tmp of an add-on container."""
    dirs = {name: tmp_path / name for name in ("data", "config", "share", "tmp")}
    for folder in dirs.values():
        folder.mkdir()
    return dirs


def start_script(
    dirs: dict[str, Path],
    options: dict[str, Any],
    supervisor: FakeSupervisor | None,
    *,
    token: str | None = TOKEN,
    metrics_port: int | None = None,
) -> subprocess.Popen[str]:
    (dirs["data"] / "options.json").write_text(json.dumps(options), encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k not in ("SUPERVISOR_TOKEN",)}
    env |= {
        "ADDON_OPTIONS": str(dirs["data"] / "options.json"),
        "ADDON_CONFIG_DIR": str(dirs["config"]),
        "ADDON_SHARE_DIR": str(dirs["share"]),
        "ADDON_GENERATED": str(dirs["tmp"] / "bridge.yaml"),
        "SUPERVISOR_API": supervisor.url if supervisor else "http://127.0.0.1:9",
        "BRIDGE_HEALTH_URL": f"http://127.0.0.1:{metrics_port or free_port()}/health",
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}",
    }
    if token is not None:
        env["SUPERVISOR_TOKEN"] = token
    return subprocess.Popen(
        [sys.executable, str(RUN)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip


def finished(process: subprocess.Popen[str]) -> tuple[int, str, str]:
    out, err = process.communicate(timeout=30)
    return process.returncode, out, err


def pump_options(port: int = 5020) -> dict[str, Any]:
    return {
        "buses": [{"id": "gw", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port,
                   "timeout": "0.5s"}],
        "devices": [{"id": "pump", "name": "Borehole pump", "bus": "gw", "unit": 1,
                     "mapping": "nastec_vasco", "poll_fast": "0.5s"}],
        "base_topic": "modbus",
        "discovery_prefix": "homeassistant",
        "log_level": "info",
    }  # fmt: skip


def own_broker_options(broker: Broker) -> dict[str, Any]:
    return {"mqtt_url": broker.url, "mqtt_username": BROKER_USER,
            "mqtt_password": BROKER_PASSWORD}  # fmt: skip


@pytest.mark.asyncio
@pytest.mark.parametrize("own", [False, True], ids=["supervisor", "mqtt_url"])
async def test_the_addon_starts_the_bridge_on_the_supervisors_broker(
    mosquitto_auth: Broker, addon_dirs: dict[str, Path], own: bool
) -> None:
    """No broker address anywhere in the options: the bridge logs in to the broker the
    Supervisor names, with its user and password, and publishes the pump. With mqtt_url
    (and its user and password) in the options, that broker is used and the Supervisor,
    which has none to give here, is not asked."""
    sim = simulator((1, "nastec_vasco"))
    observer_config = MqttConfig(url=mosquitto_auth.url, username=BROKER_USER,
                                 password=BROKER_PASSWORD)  # type: ignore[arg-type]  # fmt: skip
    answer = NO_BROKER if own else mqtt_answer(mosquitto_auth)
    extra = own_broker_options(mosquitto_auth) if own else {}
    with FakeSupervisor(answer) as supervisor:
        async with (
            serving_tcp(sim) as port,
            MqttClient(observer_config, will_topic="observer/state") as observer,
        ):
            seen: dict[str, bytes] = {}
            await observer.subscribe("homeassistant/device/pump/config", "modbus/pump/availability")
            process = start_script(addon_dirs, pump_options(port) | extra, supervisor)
            try:

                async def collect() -> None:
                    async for message in observer.messages():
                        seen[message.topic] = message.payload

                task = asyncio.create_task(collect())
                await eventually(
                    lambda: (
                        seen.get("modbus/pump/availability") == b"online"
                        and "homeassistant/device/pump/config" in seen
                    ),  # after the first values
                    40,
                )
                task.cancel()
            finally:
                process.send_signal(signal.SIGTERM)
                code, out, err = finished(process)
    assert code == 0, err
    source = "the add-on's options" if own else "the Supervisor"
    assert f"broker mqtt://127.0.0.1:{mosquitto_auth.port} (from {source})" in out
    assert supervisor.requests == ([] if own else [("/services/mqtt", f"Bearer {TOKEN}")])
    assert json.loads(seen["homeassistant/device/pump/config"])["device"]["name"] == "Borehole pump"
    written = (addon_dirs["tmp"] / "bridge.yaml").read_text(encoding="utf-8")
    assert BROKER_PASSWORD not in written  # handed over in the environment only
    assert yaml.safe_load(written)["mqtt"]["username"] == BROKER_USER
    # the page does not edit this copy: its settings live in the options
    with pytest.raises(ConfigReadOnlyError, match="the add-on's options"):
        ConfigStore.open(addon_dirs["tmp"] / "bridge.yaml").apply(
            parse_change({"kind": "remove_device", "id": "pump"})
        )


def test_no_broker_in_home_assistant_says_what_to_install(addon_dirs: dict[str, Path]) -> None:
    with FakeSupervisor(NO_BROKER) as supervisor:
        code, _, err = finished(start_script(addon_dirs, pump_options(), supervisor))
    assert code == 1
    assert "no MQTT broker in Home Assistant (Service not enabled)" in err
    assert "Mosquitto broker app" in err and "mqtt_url" in err


def test_a_broker_login_without_its_address_is_refused(addon_dirs: dict[str, Path]) -> None:
    """mqtt_username or mqtt_password alone: which broker would they log in to? Said, and
    the Supervisor's broker is not used with a login meant for another."""
    options = pump_options() | {"mqtt_username": "modbus"}
    with FakeSupervisor(A_BROKER) as supervisor:
        code, out, err = finished(start_script(addon_dirs, options, supervisor))
    assert code == 2
    assert one_line_error(err) == (
        "error: mqtt_username and mqtt_password go with mqtt_url (the broker they log in "
        "to); without mqtt_url the broker and its login are Home Assistant's\n"
    )
    assert supervisor.requests == [] and "broker" not in out


def test_an_own_broker_over_tls_is_verified(run_module: ModuleType) -> None:
    """mqtts:// from the options: TLS with the certificate checked (no 'insecure', which
    only the Supervisor's internal broker name needs)."""
    broker = run_module.own_broker({"mqtt_url": "mqtts://nas.local:8883", "mqtt_password": "x"})
    section = run_module.mqtt_section(broker, {"tls": {"insecure": True}, "qos": 0})
    assert section == {
        "qos": 0,
        "url": "mqtts://nas.local:8883",
        "password_env": run_module.PASSWORD_ENV,
    }


def test_a_wrong_token_is_a_refusal_not_a_retry(addon_dirs: dict[str, Path]) -> None:
    with FakeSupervisor(NO_BROKER) as supervisor:
        code, _, err = finished(start_script(addon_dirs, pump_options(), supervisor, token="x"))
    assert code == 1
    assert "HTTP 401 Unauthorized" in err
    assert len(supervisor.requests) == 1


def test_outside_home_assistant_there_is_no_token(addon_dirs: dict[str, Path]) -> None:
    code, _, err = finished(start_script(addon_dirs, pump_options(), None, token=None))
    assert code == 1
    assert "SUPERVISOR_TOKEN is not set" in err


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ({"devices": []}, "no devices yet"),
        ({"devices": [pump_options()["devices"][0] | {"unit": 0}]}, "devices.pump.unit:"),
        ({"devices": [pump_options()["devices"][0] | {"bus": "rs485"}]}, "devices.pump.bus:"),
        ({"devices": [pump_options()["devices"][0] | {"mapping": "no_such.yaml"}]},
         "/config/no_such.yaml: no shipped mapping of that name"),
        ({"base_topic": "$SYS"}, "mqtt.base_topic:"),
    ],
    ids=["no-devices", "unit", "bus", "mapping", "topic"],
)  # fmt: skip
def test_bad_options_name_the_field_and_start_nothing(
    addon_dirs: dict[str, Path], change: dict[str, Any], expected: str, mosquitto_auth: Broker
) -> None:
    with FakeSupervisor(mqtt_answer(mosquitto_auth)) as supervisor:
        code, out, err = finished(start_script(addon_dirs, pump_options() | change, supervisor))
    assert code == 2, err
    assert expected in err
    if "no devices" not in expected:
        assert err.startswith("error: the add-on's options: 1 error(s)\n  "), err
    assert not (addon_dirs["tmp"] / "bridge.yaml").exists()
    assert "broker" not in out


def one_line_error(err: str) -> str:
    assert "Traceback" not in err, err
    assert err.startswith("error: ") and err.count("\n") == 1 and err.endswith("\n"), err
    return err


OUTSIDE = "secret: a file the add-on must not read\n"


@pytest.mark.parametrize(
    "name",
    [
        "../outside.yaml",
        "sub/../../outside.yaml",
        "{tmp}/outside.yaml",
        "/etc/passwd",
        "link.yaml",  # a link in the add-on's folder to a file outside
        "linked/bridge.yaml",  # a linked folder outside
        "{tmp}/share/../outside.yaml",
        "{tmp}/config_evil/bridge.yaml",  # a sibling whose name starts like the folder's
    ],
)
def test_a_config_file_outside_the_addons_folder_and_share_is_refused(
    addon_dirs: dict[str, Path], name: str
) -> None:
    tmp = addon_dirs["config"].parent
    (tmp / "outside.yaml").write_text(OUTSIDE, encoding="utf-8")
    (tmp / "elsewhere").mkdir()
    (tmp / "elsewhere" / "bridge.yaml").write_text(OUTSIDE, encoding="utf-8")
    (tmp / "config_evil").mkdir()
    (tmp / "config_evil" / "bridge.yaml").write_text(OUTSIDE, encoding="utf-8")
    (addon_dirs["config"] / "sub").mkdir()
    (addon_dirs["config"] / "link.yaml").symlink_to(tmp / "outside.yaml")
    (addon_dirs["config"] / "linked").symlink_to(tmp / "elsewhere")
    options = {"buses": [], "devices": [], "config_file": name.format(tmp=tmp)}
    with FakeSupervisor(A_BROKER) as supervisor:
        code, out, err = finished(start_script(addon_dirs, options, supervisor))
    assert code == 2, err
    assert one_line_error(err).startswith(
        f"error: config_file {options['config_file']!r}: not in the add-on's folder "
        f"({addon_dirs['config']}) or under {addon_dirs['share']} (leads to "
    ), err
    assert "secret" not in err and "root:" not in err  # not read
    assert not (addon_dirs["tmp"] / "bridge.yaml").exists()
    assert "broker" not in out


@pytest.mark.parametrize(
    ("answer", "problem"),
    [
        ({}, "no 'data'"),
        (None, "null instead of an object"),
        ([], "a list instead of an object"),
        ("ok", "a string instead of an object"),
        ({"result": "ok", "data": None}, "'data' is null"),
        ({"result": "ok", "data": []}, "'data' is a list"),
        ({"result": "ok", "data": {}}, "no host; no port number"),
        ({"result": "ok", "data": {"host": "core-mosquitto", "password": "s3cret"}}, "no port number"),
        ({"result": "ok", "data": {"port": 1883, "password": "s3cret"}}, "no host"),
        ({"result": "ok", "data": SERVICE | {"port": "1883"}}, "no port number"),
        ({"result": "ok", "data": SERVICE | {"username": 5, "ssl": "no"}}, "ssl is a string; username is a number"),
    ],
)  # fmt: skip
def test_an_unexpected_answer_from_the_supervisor_is_one_line(
    addon_dirs: dict[str, Path], answer: Any, problem: str
) -> None:
    """Said at once (no retries: asking again gets the same answer), without a value from
    the answer (it holds the broker's password)."""
    with FakeSupervisor((200, answer)) as supervisor:
        code, out, err = finished(start_script(addon_dirs, pump_options(), supervisor))
    assert code == 1, err
    assert one_line_error(err) == (
        f"error: the Supervisor's answer for the MQTT service is not usable ({problem}): "
        "restart the Mosquitto broker add-on, then this add-on\n"
    )
    assert len(supervisor.requests) == 1
    assert "s3cret" not in err + out
    assert not (addon_dirs["tmp"] / "bridge.yaml").exists()


def test_every_shipped_mapping_is_offered_in_the_translations() -> None:
    text = (ADDON / "translations" / "en.yaml").read_text(encoding="utf-8")
    docs = (ADDON / "DOCS.md").read_text(encoding="utf-8")
    for name in builtin_mapping_names():
        assert name in text and name in docs, name
