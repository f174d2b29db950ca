"""``modbus-mqtt-bridge demo`` as a user runs it: five devices on MQTT, then Ctrl-C.

Each run is a real process: simulator, bridge and (for the embedded case) the amqtt
broker inside it, checked from outside through a second MQTT client.
"""

from __future__ import annotations

import asyncio
import json
import os
import pty
import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from bridge.cli.demo import SEEDS
from bridge.cli.demo_site import SITES
from bridge.config import MqttConfig
from bridge.mqtt import MqttClient
from tests.conftest import BROKER_PASSWORD, BROKER_USER
from tests.integration.mosquitto import Broker, has_mosquitto
from tests.ports import free_port

DEVICES = {seed.id for seed in SEEDS}


@contextmanager
def demo(*args: str, env: dict[str, str] | None = None) -> Iterator[subprocess.Popen[str]]:
    command = [sys.executable, "-m", "bridge.cli", "demo", "--plain", "--modbus-port", "0"]
    command += ["--web-port", "0"]  # 8099 may be another test's (the add-on's ingress port)
    with subprocess.Popen(
        [*command, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=None if env is None else os.environ | env,
    ) as process:
        try:
            yield process
        finally:
            if process.poll() is None:
                process.kill()


async def read_until(process: subprocess.Popen[str], prefix: str, within: float = 30) -> list[str]:
    """Lines of the demo's output up to the first that starts with ``prefix``."""
    assert process.stdout is not None
    lines: list[str] = []
    async with asyncio.timeout(within):
        while not lines or not lines[-1].startswith(prefix):
            line = await asyncio.to_thread(process.stdout.readline)
            assert line, f"demo ended early: {lines}"
            lines.append(line.rstrip("\n"))
    return lines


async def stop(process: subprocess.Popen[str]) -> str:
    """Ctrl-C; the demo must end cleanly and say so."""
    process.send_signal(signal.SIGINT)
    out, err = await asyncio.wait_for(asyncio.to_thread(process.communicate), 20)
    assert process.returncode == 0, err
    assert "Traceback" not in err
    return out


async def retained(url: str, pattern: str, version: str = "5", **login: str) -> dict[str, bytes]:
    config = MqttConfig(url=url, version=version, **login)  # type: ignore[arg-type]
    async with MqttClient(config, will_topic="observer/state", client_id="observer") as client:
        return await client.retained(pattern)


def discovered(configs: dict[str, bytes]) -> set[str]:
    """Device ids with a device-based discovery config (the bridge's own is not one)."""
    found = set()
    for topic, payload in configs.items():
        if payload:
            device_id = topic.split("/")[2]
            assert json.loads(payload)["cmps"], topic
            found.add(device_id)
    return found - {"modbus"}


async def discovery_of_every_device(
    url: str, version: str = "5", devices: set[str] = DEVICES, **login: str
) -> None:
    """Every seed device's (or ``devices``') discovery config arrives (bounded)."""
    found: set[str] = set()
    async with asyncio.timeout(15):
        while found != devices:
            pattern = "homeassistant/device/+/config"
            found = discovered(await retained(url, pattern, version, **login))
            await asyncio.sleep(0.2)


async def trip_and_reset_the_pump(url: str) -> None:
    """The README's fault command: the pump's alarm and status show it on MQTT; switching
    the pump off and on (it has no reset register) clears it and runs it again."""
    config = MqttConfig(url=url)
    async with MqttClient(config, will_topic="tester/state", client_id="tester") as client:
        await client.subscribe("modbus/bridge/response/demo/fault", "modbus/borehole_pump")
        body = {"device": "borehole_pump", "fault": "alarm_dry_running", "transaction": 3}
        await client.publish("modbus/bridge/request/demo/fault", json.dumps(body))
        seen: dict[str, object] = {}
        async with asyncio.timeout(15):
            async for message in client.messages():
                document = json.loads(message.payload)
                if message.topic.endswith("/demo/fault"):
                    assert document["transaction"] == 3
                    assert document["data"] == {
                        "device": "borehole_pump",
                        "faults": ["alarm_dry_running"],
                    }
                    seen["answer"] = document
                elif "alarm_dry_running" in document["alarms"]:
                    assert document["status"] == "alarm"
                    assert document["alarm_dry_running"] is True
                    seen["state"] = document
                if len(seen) == 2:
                    break
            for command in ("OFF", "ON"):
                await client.publish("modbus/borehole_pump/start_stop/set", command)
            async for message in client.messages():
                document = json.loads(message.payload)
                if message.topic == "modbus/borehole_pump" and document["status"] == "running":
                    assert document["alarms"] == []
                    break


@pytest.mark.asyncio
async def test_demo_on_a_given_broker_publishes_five_devices_and_stops(
    mosquitto: Broker,
) -> None:
    with demo("--mqtt-url", mosquitto.url) as process:
        lines = await read_until(process, "ready:")
        assert f"MQTT broker: {mosquitto.url} (given)" in lines
        assert {line.split(":")[0] for line in lines if ": online (" in line} == DEVICES
        await discovery_of_every_device(mosquitto.url)
        state: dict[str, bytes] = {}
        for _ in range(50):  # the pump reads one register per request: its values come last
            state = await retained(mosquitto.url, "modbus/borehole_pump")
            if state:
                break
            await asyncio.sleep(0.2)
        assert "status" in json.loads(state["modbus/borehole_pump"])
        await trip_and_reset_the_pump(mosquitto.url)
        out = await stop(process)
        assert out.rstrip().endswith("demo stopped; its devices were removed from the broker")
    # Home Assistant forgets the six devices: no discovery config, no retained state
    assert await retained(mosquitto.url, "homeassistant/#") == {}
    assert await retained(mosquitto.url, "modbus/#") == {}


@pytest.mark.asyncio
async def test_demo_logs_in_with_the_config_options_and_keeps_its_devices_if_asked(
    mosquitto_auth: Broker,
) -> None:
    """``--username`` and ``--password-env`` as in a config's mqtt section; ``--keep``
    leaves the devices (offline) on the broker; the password is printed nowhere."""
    env = {"DEMO_TEST_PASSWORD": BROKER_PASSWORD}
    login = ("--username", BROKER_USER, "--password-env", "DEMO_TEST_PASSWORD", "--keep")
    with demo("--mqtt-url", mosquitto_auth.url, *login, env=env) as process:
        lines = await read_until(process, "ready:")
        assert f"MQTT broker: {mosquitto_auth.url} (given, user {BROKER_USER})" in lines
        await discovery_of_every_device(
            mosquitto_auth.url, username=BROKER_USER, password=BROKER_PASSWORD
        )
        out = await stop(process)
        assert out.rstrip().endswith("demo stopped; its devices were kept on the broker (--keep)")
        assert BROKER_PASSWORD not in "\n".join(lines) + out
    credentials = {"username": BROKER_USER, "password": BROKER_PASSWORD}
    configs = await retained(mosquitto_auth.url, "homeassistant/device/+/config", **credentials)
    assert discovered(configs) == DEVICES
    kept = await retained(mosquitto_auth.url, "modbus/+/availability", **credentials)
    assert kept == {f"modbus/{d}/availability": b"offline" for d in DEVICES}


@pytest.mark.asyncio
async def test_demo_with_a_refused_login_says_so_once_and_masks_the_password(
    mosquitto_auth: Broker,
) -> None:
    url = f"mqtt://{BROKER_USER}:wrong-secret@127.0.0.1:{mosquitto_auth.port}"
    with demo("--mqtt-url", url) as process:
        _, err = await asyncio.wait_for(asyncio.to_thread(process.communicate), 30)
    assert process.returncode == 1
    assert "wrong-secret" not in err
    assert err.count("refused the connection") == 1, err
    assert "log in with --username and --password-file or --password-env" in err
    assert "Traceback" not in err


@pytest.mark.asyncio
async def test_demo_on_a_closed_port_says_so_once() -> None:
    port = free_port()
    with demo("--mqtt-url", f"mqtt://127.0.0.1:{port}") as process:
        _, err = await asyncio.wait_for(asyncio.to_thread(process.communicate), 30)
    assert process.returncode == 1
    assert err.splitlines() == [
        f"error: cannot connect to mqtt://127.0.0.1:{port}: [Errno 111] Connection refused",
        "  check --mqtt-url, or leave it out to use a local or an embedded broker",
    ]


@pytest.mark.asyncio
async def test_demo_uses_a_local_broker_that_answers(mosquitto: Broker) -> None:
    with demo("--local-broker", f"127.0.0.1:{mosquitto.port}") as process:
        lines = await read_until(process, "ready:")
        assert f"MQTT broker: {mosquitto.url} (local)" in lines
        await stop(process)


@pytest.mark.asyncio
async def test_demo_starts_an_embedded_broker_when_none_answers_if_asked() -> None:
    port = free_port()
    with demo("--local-broker", f"127.0.0.1:{port}", "--embedded-broker") as process:
        lines = await read_until(process, "ready:")
        url = f"mqtt://127.0.0.1:{port}"
        assert f"MQTT broker: {url} (embedded)" in lines
        await discovery_of_every_device(url, version="3.1.1")
        await stop(process)


@pytest.mark.asyncio
async def test_demo_starts_a_private_mosquitto_when_none_answers_and_stops_it() -> None:
    if not has_mosquitto():
        pytest.skip("no /usr/sbin/mosquitto")
    port = free_port()
    with demo("--local-broker", f"127.0.0.1:{port}") as process:
        lines = await read_until(process, "ready:")
        url = f"mqtt://127.0.0.1:{port}"
        assert f"MQTT broker: {url} (private mosquitto)" in lines
        await discovery_of_every_device(url)
        await stop(process)
    with pytest.raises(ConnectionRefusedError):  # gone with the demo
        await asyncio.open_connection("127.0.0.1", port)


def printed_commands(lines: list[str]) -> dict[str, str]:
    """The banner's shell commands by label (``watch``, ``command``, ``fault``), a line
    that ends in a backslash joined with the next, as a shell reads them."""
    text = "\n".join(lines).replace("\\\n", " ")
    found = {}
    for line in text.splitlines():
        label, sep, command = line.partition(":")
        if sep and command.strip().startswith("mosquitto_"):
            found[label] = command.strip()
    return found


class Watch:
    """A printed ``mosquitto_sub ... -v`` running in a shell; its lines as topic, payload."""

    def __init__(self, process: asyncio.subprocess.Process) -> None:
        self.process = process

    async def until(self, topic: str, holds: Callable[[str], bool], within: float = 20) -> str:
        assert self.process.stdout is not None
        async with asyncio.timeout(within):
            while line := (await self.process.stdout.readline()).decode():
                got, _, payload = line.rstrip("\n").partition(" ")
                if got == topic and holds(payload):
                    return payload
        raise AssertionError(f"mosquitto_sub ended before {topic}")


async def shell(command: str) -> None:
    """``command`` as a user types it (bash), which must succeed within 10 s."""
    process = await asyncio.create_subprocess_exec("bash", "-c", command)
    async with asyncio.timeout(10):
        assert await process.wait() == 0, command


@pytest.mark.parametrize("path", ["given", "private mosquitto", "embedded"])
@pytest.mark.asyncio
async def test_the_printed_commands_work_as_printed(path: str, tmp_path: Path) -> None:
    """The banner's watch, command and fault lines, run verbatim with mosquitto_sub and
    mosquitto_pub (QoS 0, as printed): the watch shows the pump, the command stops it, the
    fault request is answered; on an existing broker, a private mosquitto and the
    embedded broker."""
    if shutil.which("mosquitto_pub") is None or shutil.which("mosquitto_sub") is None:
        pytest.skip("mosquitto_pub/mosquitto_sub not installed (Debian: mosquitto-clients)")
    if path != "embedded" and not has_mosquitto():
        pytest.skip("no /usr/sbin/mosquitto")
    given = Broker(tmp_path)
    if path == "given":
        given.start()
    args = {
        "given": ("--mqtt-url", given.url),
        "private mosquitto": ("--local-broker", f"127.0.0.1:{free_port()}"),
        "embedded": ("--local-broker", f"127.0.0.1:{free_port()}", "--embedded-broker"),
    }[path]
    try:
        with demo(*args) as process:
            lines = await read_until(process, "ready:")
            assert any(line.endswith(f"({path})") for line in lines), lines
            commands = printed_commands(lines)
            assert set(commands) == {"watch", "command", "fault"}, lines
            sub = await asyncio.create_subprocess_exec(
                "bash",
                "-c",
                f"exec {commands['watch']}",
                stdout=asyncio.subprocess.PIPE,
                limit=2**22,  # modbus/bridge/info is long
            )
            watch = Watch(sub)
            try:
                running = await watch.until(
                    "modbus/borehole_pump", lambda p: json.loads(p)["status"] == "running"
                )
                assert json.loads(running)["start_stop"] is True
                await shell(commands["command"])
                await watch.until(
                    "modbus/borehole_pump", lambda p: json.loads(p)["status"] == "off"
                )
                await shell(commands["fault"])
                answer = await watch.until("modbus/bridge/response/demo/fault", lambda p: True)
                assert json.loads(answer)["data"]["faults"] == ["alarm_dry_running"]
            finally:
                sub.terminate()
                await sub.wait()
            await stop(process)
    finally:
        given.stop()


def test_a_bad_local_broker_address_is_refused_before_anything_starts() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "bridge.cli", "demo", "--local-broker", "nowhere"],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 2
    assert "--local-broker" in result.stderr and "HOST:PORT" in result.stderr


@pytest.mark.asyncio
async def test_demo_in_a_terminal_shows_the_live_table(mosquitto: Broker) -> None:
    """On a terminal the default view is the live table: every device shows up online, on
    an 80x24 terminal too."""
    main, side = pty.openpty()
    command = [sys.executable, "-m", "bridge.cli", "demo", "--modbus-port", "0"]
    env = os.environ | {"COLUMNS": "80", "LINES": "24", "TERM": "xterm"}
    with subprocess.Popen(
        [*command, "--mqtt-url", mosquitto.url],
        stdout=side,
        stderr=subprocess.PIPE,
        env=env,
        cwd=Path(__file__).parents[2],
    ) as process:
        os.close(side)
        screen = ""
        try:
            async with asyncio.timeout(30):
                while screen.count("online") < len(DEVICES) + 1:  # devices + "MQTT online"
                    chunk = await asyncio.to_thread(os.read, main, 65536)
                    screen = screen[-20000:] + chunk.decode(errors="replace")
            for device_id in DEVICES:
                assert device_id in screen
            process.send_signal(signal.SIGINT)
            await asyncio.wait_for(asyncio.to_thread(process.wait), 20)
            assert process.returncode == 0
        finally:
            if process.poll() is None:
                process.kill()
            os.close(main)


def taken(value: object, payload: str) -> bool:
    """A state's value is what a control's payload asked for."""
    if isinstance(value, bool):
        return value is (payload == "ON")
    if isinstance(value, int | float):
        return float(value) == float(payload)
    return value == payload


@pytest.mark.asyncio
async def test_the_home_site_runs_on_an_rs485_line_with_the_gateway(mosquitto: Broker) -> None:
    """``demo --site home``: the meter, hybrid inverter and wallbox on a virtual RS-485
    line, the heat pump on Modbus TCP, each online and discovered; the printed gateway
    read (libmodbus' mbpoll, as printed) gets the meter's voltages through the bridge;
    each of the site's controls sent on MQTT reaches the device's state; the printed
    fault raises the inverter's alarm; Ctrl-C removes the devices."""
    site = SITES["home"]
    ids = {d.id for d in site.devices}
    with demo("--site", "home", "--mqtt-url", mosquitto.url, "--gateway-port", "0") as process:
        lines = await read_until(process, "ready:")
        assert {line.split(":")[0] for line in lines if ": online (" in line} == ids, lines
        assert any("RS-485 /dev/" in line for line in lines), lines
        await discovery_of_every_device(mosquitto.url, devices=ids)
        gateway = next(line for line in lines if line.startswith("gateway: mbpoll"))
        if shutil.which("mbpoll") is not None:
            command = gateway.partition(":")[2].partition("#")[0]
            read = await asyncio.create_subprocess_exec(
                "bash", "-c", command, stdout=asyncio.subprocess.PIPE
            )
            async with asyncio.timeout(10):
                out, _ = await read.communicate()
            assert read.returncode == 0, out
            voltages = [float(v) for v in re.findall(r"^\[\d+\]:\s+(\S+)", out.decode(), re.M)]
            assert len(voltages) == 3 and all(180 < v < 280 for v in voltages), out
        config = MqttConfig(url=mosquitto.url)
        async with MqttClient(config, will_topic="tester/state", client_id="tester") as client:
            await client.subscribe(*(f"modbus/{d}" for d in ids))
            for control in site.controls:
                topic = f"modbus/{control.device}/{control.key}/set"
                await client.publish(topic, control.payload)
                async with asyncio.timeout(15):
                    async for message in client.messages():
                        document = json.loads(message.payload)
                        if message.topic == f"modbus/{control.device}" and taken(
                            document.get(control.key), control.payload
                        ):
                            break
            device, alarm = site.fault
            body = {"device": device, "fault": alarm}
            await client.publish("modbus/bridge/request/demo/fault", json.dumps(body))
            async with asyncio.timeout(15):
                async for message in client.messages():
                    document = json.loads(message.payload)
                    if message.topic == f"modbus/{device}" and alarm in document["alarms"]:
                        break
        await stop(process)
    assert discovered(await retained(mosquitto.url, "homeassistant/device/+/config")) == set()
