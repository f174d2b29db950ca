"""``modbus-mqtt-bridge demo``: the five seed devices, simulated, on MQTT in seconds.

It serves the five shipped mappings as simulated units 1..5 on a loopback Modbus TCP
port (``--site home``: a home from the device library on an RS-485 line and the LAN, with
the bridge's gateway; bridge/cli/demo_site.py), picks a broker (``--mqtt-url``, else
127.0.0.1:1883 if something answers there, else a private ``mosquitto`` of its own when
the binary is installed, else an embedded one (amqtt)), runs the real bridge against them
with Home Assistant discovery, and shows a live table of the devices, their state and the
topics to subscribe to; the web page (bridge/web) runs on loopback, its URL printed with
the table. Ctrl-C (or SIGTERM) stops everything.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import tempfile
from pathlib import Path
from typing import Any, TextIO

from bridge.app import Bridge
from bridge.cli.demo_broker import (
    BrokerChoice,
    DemoBrokerError,
    broker_advice,
    broker_how,
    choose_broker,
    free_port,
)
from bridge.cli.demo_control import FAULT_REQUEST, fault_request
from bridge.cli.demo_site import LOOPBACK, SEEDS, SERIAL_BUS, SITES, SeedDevice, Site, site_data
from bridge.cli.demo_view import DemoView, mosquitto_options, render_plain, render_table
from bridge.cli.lifecycle import add_logging_arguments, configure_logging, until_stopped
from bridge.config import LoadedConfig, load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.errors import BridgeError, ConfigError, InputError, first_of
from bridge.modbus.null_modem import null_modem
from bridge.modbus.simulator import SimulatedUnit, Simulator, SunSpecUnit
from bridge.mqtt import MqttConnectError
from bridge.sunspec.image import load_image

DESCRIPTION = """\
The five seed devices, simulated, on MQTT in seconds (no hardware needed).

It serves the five shipped mappings as simulated units 1..5 on a loopback Modbus TCP
port, picks a broker (--mqtt-url, else 127.0.0.1:1883 if something answers there, else
a private mosquitto when it is installed, else an embedded one), runs the real bridge
against them with Home Assistant discovery, and shows a live table of the devices, their
state and the topics to subscribe to.
--site home simulates a home instead: a grid meter, a hybrid inverter with its battery and
a wallbox on one RS-485 line (a virtual serial cable), which the bridge's gateway serves
to other masters on loopback TCP, and a heat pump on the LAN (Modbus TCP).
Ctrl-C (or SIGTERM) stops everything."""

DEFAULT_MODBUS_PORT = 5020
DEFAULT_WEB_PORT = 8099
DEFAULT_GATEWAY_PORT = 5502
SUNSPEC_IMAGES = Path(__file__).resolve().parent.parent / "sunspec"  # the demo's device images
__all__ = ["SEEDS", "BrokerChoice", "SeedDevice", "add_parser", "demo_config", "site_data"]


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
        "--site",
        choices=sorted(SITES),
        default="seeds",
        help="what to simulate: seeds (the five seed devices, default) or home (a grid meter, "
        "a hybrid inverter with its battery and a wallbox on one RS-485 line, served to "
        "other masters by the bridge's gateway, and a heat pump on the LAN)",
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
        "--gateway-port",
        type=int,
        default=DEFAULT_GATEWAY_PORT,
        metavar="PORT",
        help="loopback TCP port of the bridge's gateway to the home site's RS-485 line "
        f"(default {DEFAULT_GATEWAY_PORT}; a free one if taken)",
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
    placeholder = dict.fromkeys(SITES[args.site].buses, f"{LOOPBACK}:{DEFAULT_MODBUS_PORT}")
    placeholder |= {SERIAL_BUS: "/dev/null"} if SERIAL_BUS in placeholder else {}
    demo_config(
        BrokerChoice(url, "given"), placeholder, args, DEFAULT_WEB_PORT, DEFAULT_GATEWAY_PORT
    )  # refuse bad options now
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
    """Simulators, broker, bridge and view until cancelled."""
    site = SITES[args.site]
    simulators = {
        bus: Simulator([simulated_unit(d) for d in devices], tick=1.0)
        for bus in site.buses
        if (devices := site.on(bus))
    }
    with (
        contextlib.ExitStack() as cables,  # closed after the simulators' tasks have ended
        tempfile.TemporaryDirectory(prefix="bridge-demo-") as state,  # the SunSpec cache
    ):
        async with asyncio.TaskGroup() as group:
            where = _serve(simulators, group, cables, args.modbus_port)
            async with asyncio.timeout(10):
                for simulator in simulators.values():
                    await simulator.ready.wait()
            for bus, simulator in simulators.items():
                if bus != SERIAL_BUS:
                    where[bus] = f"{LOOPBACK}:{simulator.port}"
            async with choose_broker(
                args.mqtt_url, args.local_broker, args.embedded_broker
            ) as broker:
                args.state_dir = state
                await _run(site, simulators, where, broker, args=args, out=out)


def simulated_unit(device: SeedDevice) -> SimulatedUnit | SunSpecUnit:
    """A site's device as the simulator serves it: its shipped mapping, or its SunSpec
    device image (bridge/sunspec/, laid out at 40000)."""
    if device.image is not None:
        return SunSpecUnit(device.unit, load_image(SUNSPEC_IMAGES / device.image))
    return SimulatedUnit(device.unit, load_mapping(builtin_mapping_path(device.mapping)))


def _serve(
    simulators: dict[str, Simulator],
    group: asyncio.TaskGroup,
    cables: contextlib.ExitStack,
    modbus_port: int,
) -> dict[str, str]:
    """Start each bus's simulator: the RS-485 line's on one end of a virtual cable (the
    bridge opens the other end, returned), the others on loopback TCP."""
    where: dict[str, str] = {}
    for bus, simulator in simulators.items():
        if bus == SERIAL_BUS:
            device_end, where[bus] = cables.enter_context(null_modem())
            group.create_task(simulator.serve_serial(device_end), name=f"simulator {bus}")
        else:
            port = free_port(modbus_port)
            group.create_task(simulator.serve_tcp(LOOPBACK, port), name=f"simulator {bus}")
    return where


async def _run(
    site: Site,
    simulators: dict[str, Simulator],
    where: dict[str, str],
    broker: BrokerChoice,
    *,
    args: argparse.Namespace,
    out: TextIO,
) -> None:
    """The bridge on the started simulators, and the view, until cancelled."""
    web_port = free_port(args.web_port)
    gateway_port = free_port(args.gateway_port) if site.serial else 0
    loaded = demo_config(broker, where, args, web_port, gateway_port)
    bridge = Bridge(loaded, remove_on_stop=not args.keep, must_connect=True)
    units = {d.id: (simulators[d.bus], d.unit) for d in site.devices}
    bridge.extra_requests[FAULT_REQUEST] = fault_request(units)
    mqtt = loaded.config.mqtt
    view = DemoView(bridge, broker_url=mqtt.broker_url, broker_how=broker_how(broker, mqtt))
    view.modbus = _modbus_line(site, where, gateway_port)
    command = site.controls[0]
    view.command = f"{args.base_topic}/{command.device}/{command.key}/set"
    view.command_payload = command.payload
    fault = f"{args.base_topic}/bridge/request/{FAULT_REQUEST}"
    device, alarm = site.fault
    view.extra += [
        f"fault:   mosquitto_pub{mosquitto_options(mqtt)} -t {fault} -m \\",
        f"""           '{{"device": "{device}", "fault": "{alarm}"}}'""",
    ]
    if site.serial:
        served = ",".join(str(d.unit) for d in site.serial)
        view.extra.append(
            f"gateway: mbpoll -m tcp -p {gateway_port} {site.gateway_read} {LOOPBACK}"
            f"  # units {served} of the RS-485 line, through the bridge"
        )
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
        raise DemoBrokerError(broker_advice(failure, broker)) from None


def _modbus_line(site: Site, where: dict[str, str], gateway_port: int) -> str:
    """Where the simulated devices are, as the banner says it."""
    parts = []
    for bus in site.buses:
        if bus == SERIAL_BUS:
            parts.append(f"RS-485 {where[bus]} (RTU 9600 8N1)")
        else:
            parts.append(f"Modbus TCP {where[bus]}")
    if gateway_port:
        parts.append(f"gateway Modbus TCP {LOOPBACK}:{gateway_port}")
    return ", ".join(parts)


def demo_config(
    broker: BrokerChoice,
    where: dict[str, str],
    args: argparse.Namespace,
    web_port: int = DEFAULT_WEB_PORT,
    gateway_port: int = 0,
) -> LoadedConfig:
    """The bridge config of the demo's site (``args.site``): its buses at ``where`` (bus id
    -> serial port or loopback host:port), the web page on loopback, the gateway on
    ``gateway_port`` for a site with an RS-485 line, and the broker with the login options
    (validated like a config file's ``mqtt`` section; errors name the options)."""
    login = {
        "username": args.username,
        "password_file": args.password_file,
        "password_env": args.password_env,
    }
    if broker.own:  # anonymous: the login options are for a real broker
        login = {}
    site = SITES[args.site]
    mqtt: dict[str, Any] = {
        "url": broker.url,
        "version": broker.protocol,
        "base_topic": args.base_topic,
        "client_id": f"modbus-mqtt-bridge-demo-{web_port}",
    } | {name: value for name, value in login.items() if value is not None}
    state_dir = getattr(args, "state_dir", None)
    try:
        return _site_config(site, mqtt, where, web_port, gateway_port, state_dir)
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


def _site_config(  # noqa: PLR0917 - the demo's own
    site: Site,
    mqtt: dict[str, Any],
    where: dict[str, str],
    web_port: int,
    gateway_port: int,
    state_dir: str | None,
) -> LoadedConfig:
    data = site_data(site, mqtt, where, web_port, gateway_port)
    if state_dir is not None:
        data["bridge"]["state_dir"] = state_dir
    return load_config_data(data, Path(f"demo-{site.name}.yaml"))


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
