"""``modbus-mqtt-bridge demo``: the five seed devices, simulated, on MQTT in seconds.

It serves the five shipped mappings as simulated units 1..5 on a loopback Modbus TCP
port, picks a broker (``--mqtt-url``, else 127.0.0.1:1883 if something answers there,
else a private ``mosquitto`` of its own when the binary is installed, else an embedded one
(amqtt)), runs the real bridge against them with Home Assistant discovery,
and shows a live table of the devices, their state and the topics to subscribe to; the
web page (bridge/web) runs on loopback, its URL printed with the table.
Ctrl-C (or SIGTERM) stops everything.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import socket
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from bridge.app import Bridge
from bridge.cli.demo_broker import find_mosquitto, private_mosquitto
from bridge.cli.demo_control import FAULT_REQUEST, fault_request
from bridge.cli.demo_view import DemoView, mosquitto_options, render_plain, render_table
from bridge.cli.lifecycle import add_logging_arguments, configure_logging, until_stopped
from bridge.config import LoadedConfig, MqttConfig, load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.errors import BridgeError, ConfigError, InputError, first_of
from bridge.modbus.simulator import SimulatedUnit, Simulator
from bridge.mqtt import MqttConnectError
from bridge.mqtt.broker import PROTOCOL, embedded_broker

DESCRIPTION = """\
The five seed devices, simulated, on MQTT in seconds (no hardware needed).

It serves the five shipped mappings as simulated units 1..5 on a loopback Modbus TCP
port, picks a broker (--mqtt-url, else 127.0.0.1:1883 if something answers there, else
a private mosquitto when it is installed, else an embedded one), runs the real bridge
against them with Home Assistant discovery, and shows a live table of the devices, their
state and the topics to subscribe to.
Ctrl-C (or SIGTERM) stops everything."""
LOOPBACK = "127.0.0.1"
DEFAULT_MODBUS_PORT = 5020
DEFAULT_WEB_PORT = 8099


@dataclass(frozen=True, slots=True)
class SeedDevice:
    id: str
    name: str
    mapping: str
    unit: int


SEEDS = (
    SeedDevice("borehole_pump", "Borehole pump", "nastec_vasco", 1),
    SeedDevice("fan_drive", "Fan drive", "p2_vfd", 2),
    SeedDevice("booster_starter", "Booster starter", "soft_starter", 3),
    SeedDevice("main_drive", "Main drive", "vacon_nx", 4),
    SeedDevice("genset", "Genset", "smartgen_hgm6100", 5),
)


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


def add_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    demo = commands.add_parser(
        "demo",
        help="simulate the five seed devices and bridge them to MQTT (no hardware needed)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    demo.add_argument(
        "--mqtt-url",
        metavar="URL",
        help="broker to use: mqtt://host:port (mqtt://user:password@host:port logs in; the "
        "password is shown nowhere)",
    )
    login = demo.add_argument_group("broker login (as mqtt.username, password_file, password_env)")
    login.add_argument("--username", metavar="NAME", help="user name on the broker")
    secret = login.add_mutually_exclusive_group()
    secret.add_argument(
        "--password-file", type=Path, metavar="FILE", help="file holding the password"
    )
    secret.add_argument(
        "--password-env", metavar="VARIABLE", help="environment variable holding the password"
    )
    demo.add_argument(
        "--modbus-port",
        type=int,
        default=DEFAULT_MODBUS_PORT,
        metavar="PORT",
        help=f"loopback TCP port of the simulated devices (default {DEFAULT_MODBUS_PORT}; "
        "a free one if taken)",
    )
    demo.add_argument(
        "--web-port",
        type=int,
        default=DEFAULT_WEB_PORT,
        metavar="PORT",
        help=f"loopback TCP port of the web page (default {DEFAULT_WEB_PORT}, the add-on's "
        "ingress port; a free one if taken; 0: any free one)",
    )
    demo.add_argument(
        "--local-broker",
        default=f"{LOOPBACK}:1883",
        metavar="HOST:PORT",
        help="where to look for a running broker before starting one of its own (a "
        "private mosquitto if installed, else an embedded one; default %(default)s: the "
        "demo's broker takes this port when it is free)",
    )
    demo.add_argument(
        "--embedded-broker",
        action="store_true",
        help="when no broker answers, run the embedded one (amqtt) even if mosquitto is installed",
    )
    demo.add_argument("--base-topic", default="modbus", metavar="TOPIC")
    demo.add_argument(
        "--keep",
        action="store_true",
        help="leave the devices on the broker at the end (default: Ctrl-C removes their "
        "discovery configs and retained state, so Home Assistant forgets them)",
    )
    demo.add_argument(
        "--plain", action="store_true", help="print state changes as lines, no live table"
    )
    add_logging_arguments(demo, level="warning")
    demo.set_defaults(handler=run_demo)


def run_demo(args: argparse.Namespace, out: TextIO) -> int:
    host, _, port = args.local_broker.rpartition(":")
    if not host or not port.isdigit():
        raise InputError("--local-broker", [f"use HOST:PORT, not {args.local_broker!r}"])
    url = args.mqtt_url or f"mqtt://{args.local_broker}"
    demo_config(BrokerChoice(url, "given"), DEFAULT_MODBUS_PORT, args)  # refuse bad options now
    configure_logging(args.log_level, args.log_format)
    try:
        asyncio.run(until_stopped(demo(args, out)))
    except ExceptionGroup as failed:
        reason = first_of(failed, BridgeError)
        if reason is None:
            raise
        print(f"error: {reason}", file=sys.stderr)
        return 1
    gone = "kept on the broker (--keep)" if args.keep else "removed from the broker"
    print(f"demo stopped; its devices were {gone}", file=out, flush=True)
    return 0


async def demo(args: argparse.Namespace, out: TextIO) -> None:
    """Simulator, broker, bridge and view until cancelled."""
    simulator = Simulator(
        [SimulatedUnit(s.unit, load_mapping(builtin_mapping_path(s.mapping))) for s in SEEDS],
        tick=1.0,
    )
    async with asyncio.TaskGroup() as group:
        port = _free_port(args.modbus_port)
        group.create_task(simulator.serve_tcp(LOOPBACK, port, "socket"), name="simulator")
        async with asyncio.timeout(10):
            await simulator.ready.wait()
        async with _broker(args.mqtt_url, args.local_broker, args.embedded_broker) as broker:
            web_port = _free_port(args.web_port)
            loaded = demo_config(broker, simulator.port, args, web_port)
            bridge = Bridge(loaded, remove_on_stop=not args.keep, must_connect=True)
            units = {seed.id: seed.unit for seed in SEEDS}
            bridge.extra_requests[FAULT_REQUEST] = fault_request(simulator, units)
            mqtt = loaded.config.mqtt
            view = DemoView(bridge, broker_url=mqtt.broker_url, broker_how=_how(broker, mqtt))
            view.modbus = f"{LOOPBACK}:{simulator.port}"
            fault = f"{args.base_topic}/bridge/request/{FAULT_REQUEST}"
            view.extra += [
                f"fault:   mosquitto_pub{mosquitto_options(mqtt)} -t {fault} -m \\",
                f"""           '{{"device": "{SEEDS[0].id}", "fault": "alarm_dry_running"}}'""",
            ]
            view.extra.append(
                "Ctrl-C stops: the devices stay on the broker (--keep)"
                if args.keep
                else "Ctrl-C stops and removes the devices from the broker (--keep: keeps)"
            )
            try:
                async with asyncio.TaskGroup() as inner:
                    inner.create_task(bridge.run(), name="bridge")
                    show = _show_plain if args.plain or not out.isatty() else _show_live
                    await show(view, out)
            except* MqttConnectError as failed:
                failure = first_of(failed, MqttConnectError) or failed
                raise DemoBrokerError(_advice(failure, broker)) from None


class DemoBrokerError(BridgeError):
    """The broker the demo chose cannot be used (unreachable, login refused)."""


def _how(broker: BrokerChoice, mqtt: MqttConfig) -> str:
    """``local``, ``given, user bridge``: how the broker was chosen, and the login."""
    return broker.how + (f", user {mqtt.username}" if mqtt.username else "")


def _advice(failure: Exception, broker: BrokerChoice) -> str:
    """Why the demo cannot use the broker, and what to do, said once."""
    if isinstance(failure, MqttConnectError) and failure.refused:  # the login
        hint = "log in with --username and --password-file or --password-env"
    elif broker.how == "given":
        hint = "check --mqtt-url, or leave it out to use a local or an embedded broker"
    else:
        hint = "name another broker with --mqtt-url or --local-broker HOST:PORT"
    return f"{failure}\n  {hint}"


def demo_config(
    broker: BrokerChoice,
    modbus_port: int,
    args: argparse.Namespace,
    web_port: int = DEFAULT_WEB_PORT,
) -> LoadedConfig:
    """The bridge config of the demo: the five seed devices on one loopback TCP bus, the
    web page on loopback, and the broker with the login options (validated like a config
    file's ``mqtt`` section; errors name the options)."""
    login = {
        "username": args.username,
        "password_file": args.password_file,
        "password_env": args.password_env,
    }
    if broker.own:  # anonymous: the login options are for a real broker
        login = {}
    mqtt: dict[str, Any] = {
        "url": broker.url,
        "version": broker.protocol,
        "base_topic": args.base_topic,
        "client_id": f"modbus-mqtt-bridge-demo-{modbus_port}",
    } | {name: value for name, value in login.items() if value is not None}
    try:
        return _seeds_config(mqtt, modbus_port, web_port)
    except ConfigError as exc:
        raise InputError("demo", [_as_option(issue) for issue in exc.issues]) from None


def _as_option(issue: str) -> str:
    """``mqtt.password_env: ...`` as the option a user gave: ``--password-env: ...``."""
    location, sep, message = issue.partition(": ")
    field = location.removeprefix("mqtt.")
    if location.startswith("mqtt.") and field in _OPTIONS:
        return f"{_OPTIONS[field]}{sep}{message}"
    return issue


_OPTIONS = {
    "url": "--mqtt-url",
    "username": "--username",
    "password_file": "--password-file",
    "password_env": "--password-env",
    "base_topic": "--base-topic",
}


def _seeds_config(mqtt: dict[str, Any], modbus_port: int, web_port: int) -> LoadedConfig:
    data: dict[str, Any] = {
        "mqtt": mqtt,
        "bridge": {"web": {"enabled": True, "port": web_port}},
        "buses": [
            {
                "id": "demo",
                "transport": "tcp",
                "host": LOOPBACK,
                "tcp_port": modbus_port,
                "timeout": 0.5,
            }
        ],
        "devices": [
            {"id": s.id, "name": s.name, "bus": "demo", "unit": s.unit, "mapping": s.mapping}
            for s in SEEDS
        ],
    }
    return load_config_data(data, Path("demo.yaml"))


@contextlib.asynccontextmanager
async def _broker(url: str | None, local: str, embedded: bool) -> AsyncIterator[BrokerChoice]:
    """The broker given, else a local one that answers, else a private mosquitto, else an
    embedded one (both on ``local``'s port if it is free)."""
    if url is not None:
        yield BrokerChoice(url, "given")
        return
    host, _, port_text = local.rpartition(":")
    if await _answers(host, int(port_text)):
        yield BrokerChoice(f"mqtt://{host}:{port_text}", "local")
        return
    port = _free_port(int(port_text))
    mosquitto = None if embedded else find_mosquitto()
    if mosquitto is not None:
        async with private_mosquitto(mosquitto, LOOPBACK, port) as private:
            yield BrokerChoice(private, PRIVATE)
        return
    async with embedded_broker(LOOPBACK, port) as inside:
        yield BrokerChoice(inside, EMBEDDED, PROTOCOL)


async def _answers(host: str, port: int) -> bool:
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


def _free_port(preferred: int) -> int:
    """``preferred`` if it can be bound on loopback, else a free port the OS picks."""
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((LOOPBACK, preferred))
        except OSError:
            probe.bind((LOOPBACK, 0))
        return int(probe.getsockname()[1])


async def _show_live(view: DemoView, out: TextIO) -> None:
    from rich.console import Console  # noqa: PLC0415 - only for the terminal view
    from rich.live import Live  # noqa: PLC0415

    console = Console(file=out)
    with Live(render_table(view), console=console, refresh_per_second=2) as live:
        while True:
            await asyncio.sleep(0.5)
            live.update(render_table(view))


async def _show_plain(view: DemoView, out: TextIO) -> None:
    for line in view.banner():
        print(line, file=out, flush=True)
    while True:
        for line in render_plain(view):
            print(line, file=out, flush=True)
        await asyncio.sleep(0.2)
