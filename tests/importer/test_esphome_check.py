"""An ESPHome node checked by ESPHome itself (``esphome config``): what ESPHome refuses is
reported in its words at the entity's file and line; without ESPHome the import says once
that the node was not checked. The tests that run ESPHome need it installed (``make
esphome``: a cached venv of its own); they are skipped, saying so, without it."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.importer.esphome_check import ESPHOME_ENV, Refusal, parse_report

CACHED = Path.home() / ".cache" / "modbus-mqtt-bridge" / "esphome" / "bin" / "esphome"
NODE = """\
esphome:
  name: meter
esp32:
  board: esp32dev
wifi:
  ssid: !secret wifi_ssid
  password: !secret wifi_password
uart:
  tx_pin: 17
  rx_pin: 16
  baud_rate: 9600
modbus:
  id: modbus1
modbus_controller:
  - id: meter
    address: 1
    modbus_id: modbus1
sensor:
  - platform: modbus_controller
    modbus_controller_id: meter
    name: Energy
    address: 10
    register_type: REGISTER
    value_type: U_QWORD
"""
# ESPHome 2026.10's words for the node above with `register_type: nonsense` (its output,
# as `esphome config` printed it)
REFUSED = """\
INFO ESPHome 2026.10.0
INFO Reading configuration node.yaml...
Failed config

sensor.modbus_controller: [source node.yaml:19]
  platform: modbus_controller
  modbus_controller_id: meter
  name: Energy
  address: 10
  \n\
  Unknown value 'nonsense', valid options are 'custom', 'coil', 'holding', 'discrete_input', 'read', 'input'.
  register_type: nonsense
  value_type: U_QWORD
"""


def esphome() -> str:
    """The ESPHome to run, or skip saying how to get one."""
    given = os.environ.get(ESPHOME_ENV) or (str(CACHED) if CACHED.exists() else None)
    if not given:
        pytest.skip(f"ESPHome is not installed ({CACHED} is missing): `make esphome` makes it")
    return given


def imported(
    tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str], *, secrets: str | None = None
) -> tuple[int, str]:
    folder = tmp_path / "node"
    folder.mkdir(parents=True)
    (folder / "node.yaml").write_text(text, encoding="utf-8")
    if secrets is not None:
        (folder / "secrets.yaml").write_text(secrets, encoding="utf-8")
    code = main(["import", "esphome", str(folder / "node.yaml"), "--out", str(tmp_path / "out")])
    return code, capsys.readouterr().err


def test_a_refusal_is_read_from_esphomes_report() -> None:
    assert parse_report(REFUSED) == [
        Refusal(
            "sensor.modbus_controller",
            "node.yaml",
            19,
            "Unknown value 'nonsense', valid options are 'custom', 'coil', 'holding', "
            "'discrete_input', 'read', 'input'.",
            "register_type",
        )
    ]


def test_a_refusal_of_the_whole_node_and_a_valid_node() -> None:
    missing = "INFO Reading configuration x.yaml...\nFailed config\n\n'esphome' section missing.\n"
    assert parse_report(missing) == [Refusal("", "", 0, "'esphome' section missing.")]
    assert parse_report("INFO Reading configuration x.yaml...\nesphome:\n  name: x\n") == []


def test_without_esphome_the_node_is_said_to_be_unchecked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(ESPHOME_ENV, str(tmp_path / "no-esphome"))
    code, err = imported(tmp_path, NODE.replace("REGISTER", "nonsense"), capsys)
    assert code == 2  # nothing usable: the import's own judgement of the table
    assert err.count("esphome config: partly converted: ESPHome is not installed here") == 1
    assert "ESPHome refuses" not in err


def test_esphome_refuses_a_key_in_its_own_words_at_its_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(ESPHOME_ENV, esphome())
    code, err = imported(tmp_path, NODE.replace("REGISTER", "nonsense"), capsys)
    assert code == 2
    assert (
        "node.yaml:23: Energy.register_type: not converted: ESPHome refuses it: Unknown value "
        "'nonsense', valid options are 'custom', 'coil', 'holding', 'discrete_input', 'read', "
        "'input'. (ESPHome stops at its first refusal: fix it and import again)"
    ) in err
    assert "node.yaml:23: Energy.register_type: not converted: not a table" not in err


def test_an_unknown_key_is_esphomes_to_refuse(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The import's own 'an option the bridge has not' gives way to ESPHome's refusal."""
    monkeypatch.setenv(ESPHOME_ENV, esphome())
    node = NODE.replace("REGISTER", "read") + "    colour: red\n"
    code, err = imported(tmp_path, node, capsys)
    assert code == 0
    assert "node.yaml:25: Energy.colour: not converted: ESPHome refuses it: [colour] is an " in err
    assert "an ESPHome option the bridge has not" not in err


def test_a_node_esphome_accepts_is_reported_as_before(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without a secrets.yaml beside the node the run gets placeholders; with one, its own."""
    monkeypatch.setenv(ESPHOME_ENV, esphome())
    code, err = imported(tmp_path, NODE.replace("REGISTER", "read"), capsys)
    assert code == 0
    assert "ESPHome refuses" not in err
    assert "not installed" not in err
    secrets = "wifi_ssid: home\nwifi_password: long enough\n"
    code, err = imported(
        tmp_path / "second", NODE.replace("REGISTER", "read"), capsys, secrets=secrets
    )
    assert code == 0
    assert "ESPHome refuses" not in err
    out = tmp_path / "out" / "mappings" / "meter.yaml"
    assert "type: u64" in out.read_text(encoding="utf-8")
