"""A real Home Assistant, headless, for the tests in tests/ha.

``tools/ha_env.sh`` installs each supported version in its own venv inside a Debian
testing chroot (``~/.cache/modbus-mqtt-bridge/ha-forky/opt/ha-<version>``); ``HomeAssistant`` starts one of them
(``chroot ROOT /opt/ha-<version>/bin/hass -c DIR``) with a config folder in the chroot's
/tmp, onboards a user over HTTP for an access token, sets up the MQTT integration through
its config flow against the test's broker, and answers websocket commands (the entity and
device registries, the states, the recorder's statistics). ``integrations`` adds
integrations to configuration.yaml (``("recorder",)`` for long-term statistics: the
harness's own config loads no recorder). ``log_records()`` parses ``home-assistant.log`` into
records (a record's continuation lines, a traceback, belong to it): Home Assistant 2025.x
writes ``2025-11-27 19:00:00.123 WARNING (MainThread) [logger] message``, 2026.x adds
the UTC offset to the time (``19:00:00.123+00:00``).
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import shutil
import subprocess
import tempfile
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from websockets.asyncio.client import ClientConnection, connect

from tests.ports import free_port

# uv (which installs the integrations' requirements) trusts the chroot's certificate store only
# with UV_NATIVE_TLS (tools/ha_env.sh adds the host's authorities to it)
CLEAN_ENV = [
    "env",
    "-i",
    "PATH=/usr/sbin:/usr/bin:/sbin:/bin",
    "HOME=/root",
    "LANG=C.UTF-8",
    "UV_NATIVE_TLS=true",
]
START_TIMEOUT = 240.0  # a first start installs the integrations' requirements
_RECORD = re.compile(
    r"^(?P<time>\d{4}-\d\d-\d\d \d\d:\d\d:\d\d(?:\.\d+)?(?:[+-]\d\d:?\d\d|Z)?) "
    r"(?P<level>[A-Z]+) \((?P<thread>[^)]*)\) \[(?P<logger>[^\]]+)\] (?P<message>.*)$"
)


@dataclass(frozen=True)
class LogRecord:
    time: str
    level: str
    logger: str
    message: str  # with its continuation lines

    def __str__(self) -> str:
        return f"{self.time} {self.level} [{self.logger}] {self.message}"


def parse_log(text: str) -> list[LogRecord]:
    """The records of a home-assistant.log, 2025.x and 2026.x formats alike; lines before
    the first record are dropped, later lines that start no record continue the last."""
    records: list[LogRecord] = []
    for line in text.splitlines():
        match = _RECORD.match(line)
        if match:
            records.append(
                LogRecord(match["time"], match["level"], match["logger"], match["message"])
            )
        elif records:
            last = records[-1]
            records[-1] = LogRecord(last.time, last.level, last.logger, f"{last.message}\n{line}")
    return records


CONFIGURATION = """\
homeassistant:
  name: Test
  latitude: 52.0
  longitude: 4.0
  elevation: 0
  unit_system: metric
  time_zone: UTC
  currency: EUR
  country: NL
http:
  server_host: 127.0.0.1
  server_port: {port}
api:
websocket_api:
config:
onboarding:
logger:
  default: warning
"""


def form_answer(schema: list[dict[str, Any]], given: dict[str, Any]) -> dict[str, Any]:
    """A config flow form filled in: ``given`` values, else each field's default, else for
    a required field false (a boolean) or the first option (a select); an expandable
    section (2026.x puts MQTT's advanced options in one) filled in the same way."""
    answer: dict[str, Any] = {}
    for item in schema:
        name = item["name"]
        if item.get("type") == "expandable":
            answer[name] = form_answer(item["schema"], given)
        elif name in given:
            answer[name] = given[name]
        elif "default" in item:
            answer[name] = item["default"]
        elif item.get("required"):
            selector = item.get("selector", {})
            if "boolean" in selector:
                answer[name] = False
            elif "select" in selector:
                option = selector["select"]["options"][0]
                answer[name] = option["value"] if isinstance(option, dict) else option
    return answer


@dataclass
class HomeAssistant:
    root: Path  # the chroot
    version: str
    integrations: tuple[str, ...] = ()  # loaded besides the harness's own, with no options
    extra_yaml: str = ""  # appended to configuration.yaml as is (a `modbus:` block, say)
    port: int = 0
    workdir: Path | None = None
    process: subprocess.Popen[bytes] | None = None
    token: str = ""
    _message_id: int = field(default=0, repr=False)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def config_dir(self) -> Path:
        assert self.workdir is not None
        return self.workdir

    @property
    def log_text(self) -> str:
        path = self.config_dir / "home-assistant.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def log_records(self) -> list[LogRecord]:
        return parse_log(self.log_text)

    def start(self) -> None:
        tmp = self.root / "tmp"
        tmp.mkdir(exist_ok=True)
        self.workdir = Path(tempfile.mkdtemp(prefix="ha-", dir=tmp))
        self.port = free_port()
        self.write_configuration()
        self._launch()
        self._onboard()
        asyncio.run(self._confirm_http_config())

    async def _confirm_http_config(self) -> None:
        """Confirm the HTTP config (our port) as working: 2026.11 tries a changed one for
        five minutes, then reverts to the last confirmed (port 8123) and restarts. Older
        versions have no such command, and nothing to confirm."""
        socket = await self.websocket()
        try:
            await socket.call("http/config/promote")
        except RuntimeError as refused:  # unknown command (older), or nothing pending
            if "unknown_command" not in str(refused) and "promote" not in str(refused):
                raise
        finally:
            await socket.close()

    def write_configuration(self) -> None:
        """configuration.yaml from the harness's own, ``integrations`` and ``extra_yaml``
        (change ``extra_yaml`` and call this, then ``restart``, to change the config)."""
        extra = "".join(f"{name}:\n" for name in self.integrations)
        (self.config_dir / "configuration.yaml").write_text(
            CONFIGURATION.format(port=self.port) + extra + self.extra_yaml
        )

    def restart(self) -> None:
        """Stop and start again on the same config folder (entities, registries, recorder
        and the access token kept)."""
        self.stop()
        self._launch()

    def _launch(self) -> None:
        inside = "/" + str(self.config_dir.relative_to(self.root))
        hass = f"/opt/ha-{self.version}/bin/hass"
        with (self.config_dir / "stdout.log").open("ab") as output:
            self.process = subprocess.Popen(
                ["chroot", str(self.root), *CLEAN_ENV, hass, "-c", inside],
                stdout=output,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        self._wait_until_up()

    def _wait_until_up(self) -> None:
        deadline = time.monotonic() + START_TIMEOUT
        while time.monotonic() < deadline:
            assert self.process is not None
            if self.process.poll() is not None:
                raise RuntimeError(f"Home Assistant exited:\n{self.tail()}")
            try:
                with urllib.request.urlopen(f"{self.url}/api/onboarding", timeout=2) as answer:
                    if answer.status == 200:
                        return
            except OSError:
                pass
            time.sleep(0.5)
        raise RuntimeError(f"Home Assistant did not answer in {START_TIMEOUT} s:\n{self.tail()}")

    def tail(self, lines: int = 40) -> str:
        out = (self.config_dir / "stdout.log").read_text(errors="replace")
        return "\n".join((out or self.log_text).splitlines()[-lines:])

    def _post(self, path: str, body: dict[str, Any], *, form: bool = False) -> Any:
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        if form:
            data = "&".join(f"{k}={v}" for k, v in body.items()).encode()
            headers["Content-Type"] = "application/x-www-form-urlencoded"
        else:
            data = json.dumps(body).encode()
            headers["Content-Type"] = "application/json"
        request = urllib.request.Request(self.url + path, data=data, headers=headers)
        with urllib.request.urlopen(request, timeout=60) as answer:
            return json.loads(answer.read())

    def _onboard(self) -> None:
        client_id = f"{self.url}/"
        user = self._post(
            "/api/onboarding/users",
            {
                "client_id": client_id,
                "name": "Test",
                "username": "test",
                "password": "test-password",
                "language": "en",
            },
        )
        token = self._post(
            "/auth/token",
            {"grant_type": "authorization_code", "code": user["auth_code"], "client_id": client_id},
            form=True,
        )
        self.token = token["access_token"]

    def add_mqtt(self, host: str, port: int) -> dict[str, Any]:
        """Set up the MQTT integration through its config flow (discovery on, prefix
        ``homeassistant``); returns the flow's last answer."""
        step = self._post("/api/config/config_entries/flow", {"handler": "mqtt"})
        for _ in range(5):
            if step["type"] != "form":
                break
            given = {"broker": host, "port": port} if step["step_id"] == "broker" else {}
            step = self._post(
                f"/api/config/config_entries/flow/{step['flow_id']}",
                form_answer(step["data_schema"], given),
            )
        if step["type"] != "create_entry":
            raise RuntimeError(f"the MQTT config flow ended with {step}")
        return dict(step)

    async def websocket(self) -> HomeAssistantSocket:
        connection = await connect(f"ws://127.0.0.1:{self.port}/api/websocket", max_size=None)
        await connection.recv()  # auth_required
        await connection.send(json.dumps({"type": "auth", "access_token": self.token}))
        answer = json.loads(await connection.recv())
        if answer["type"] != "auth_ok":
            raise RuntimeError(f"websocket authentication refused: {answer}")
        return HomeAssistantSocket(connection)

    def stop(self) -> None:
        if self.process is None:
            return
        if self.process.poll() is None:
            os.killpg(self.process.pid, 15)
            try:
                self.process.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, 9)
                self.process.wait(10)
        self.process = None

    def remove(self) -> None:
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)


@dataclass
class HomeAssistantSocket:
    connection: ClientConnection
    next_id: int = 1

    async def call(self, kind: str, **fields: Any) -> Any:
        message_id = self.next_id
        self.next_id += 1
        await self.connection.send(json.dumps({"id": message_id, "type": kind, **fields}))
        while True:
            answer = json.loads(await self.connection.recv())
            if answer.get("id") == message_id and answer.get("type") == "result":
                if not answer["success"]:
                    raise RuntimeError(f"{kind}: {answer['error']}")
                return answer["result"]

    async def entities(self) -> list[dict[str, Any]]:
        """The entity registry's MQTT entries."""
        entries = await self.call("config/entity_registry/list")
        return [e for e in entries if e.get("platform") == "mqtt"]

    async def devices(self) -> list[dict[str, Any]]:
        return list(await self.call("config/device_registry/list"))

    async def states(self) -> dict[str, dict[str, Any]]:
        return {s["entity_id"]: s for s in await self.call("get_states")}

    async def statistics(
        self, statistic_ids: list[str], start: str, period: str = "5minute"
    ) -> dict[str, list[dict[str, Any]]]:
        """The recorder's compiled statistics (``sum`` and ``state``) of ``statistic_ids``
        from ``start`` (ISO 8601), one row per ``period``: statistic id -> rows in time
        order, each with ``start`` and ``end`` in epoch milliseconds; an id with nothing
        compiled yet is absent."""
        return dict(
            await self.call(
                "recorder/statistics_during_period",
                start_time=start,
                statistic_ids=statistic_ids,
                period=period,
                types=["sum", "state"],
            )
        )

    async def close(self) -> None:
        await self.connection.close()
