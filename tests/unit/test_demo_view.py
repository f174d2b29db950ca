"""The demo's live table fits an 80x24 terminal: one line per device, status as a label."""

from __future__ import annotations

import argparse
import io

import pytest
from rich.console import Console

from bridge.app import Bridge
from bridge.cli.demo import SEEDS, BrokerChoice, demo_config
from bridge.cli.demo_view import DemoView, mosquitto_options, render_table, status_label
from bridge.config import MqttConfig
from bridge.core.codec import decode
from bridge.core.simulation import initial_image


def demo_bridge(**login: str) -> Bridge:
    """The demo's bridge, not running, its pollers holding what the simulator starts with."""
    options = {"username": None, "password_file": None, "password_env": None} | login
    args = argparse.Namespace(base_topic="modbus", site="seeds", **options)
    where = {"demo": "127.0.0.1:5020"}
    bridge = Bridge(demo_config(BrokerChoice("mqtt://127.0.0.1:1883", "local"), where, args))
    for poller in bridge.engine.devices.values():
        image = initial_image(poller.mapping, poller.points)
        poller.image.update(image)
        for key, point in poller.points.items():
            if point.entity.readable:
                poller.values[key] = decode(point, image)
        poller.health.online = True
    return bridge


def screen(bridge: Bridge, width: int = 80) -> list[str]:
    view = DemoView(bridge, "mqtt://127.0.0.1:1883", "local", modbus="127.0.0.1:5020")
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(render_table(view))
    return console.export_text().splitlines()


def test_the_table_fits_80_columns_and_24_lines_one_line_per_device() -> None:
    lines = screen(demo_bridge())
    assert max(len(line) for line in lines) <= 80
    assert len(lines) <= 24
    for seed in SEEDS:
        (row,) = [line for line in lines if line.startswith(f"{seed.id} ")]
        assert "online" in row
    vacon = next(line for line in lines if line.startswith("main_drive "))
    assert "running" in vacon.split()  # the status label, not True
    assert "True" not in vacon and "Status word" not in vacon  # no flags or raw words


def test_a_boolean_status_reads_as_its_name() -> None:
    bridge = demo_bridge()
    vacon = bridge.engine.devices["main_drive"]
    assert status_label(vacon) == "running"
    vacon.values["running"] = False
    assert status_label(vacon) == "not running"
    vacon.values["running"] = None
    assert status_label(vacon) == "-"


@pytest.mark.parametrize(
    ("url", "login", "shown"),
    [
        ("mqtt://127.0.0.1:1883", {}, ""),
        ("mqtt://192.0.2.7:1884", {}, " -h 192.0.2.7 -p 1884"),
        ("mqtt://127.0.0.1", {"username": "ha", "password_env": "PW"}, ' -u ha -P "$PW"'),
        ("mqtt://ha:s3cret@127.0.0.1", {}, " -u ha -P PASSWORD"),
    ],
)
def test_commands_shown_carry_the_login_but_never_the_password(
    url: str, login: dict[str, str], shown: str
) -> None:
    assert mosquitto_options(MqttConfig(url=url, **login)) == shown  # type: ignore[arg-type]
