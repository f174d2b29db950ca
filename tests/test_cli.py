"""The console script: check, schema, mappings list/show/validate, exit codes."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.app import Bridge
from bridge.cli import console as cli
from bridge.cli import main
from bridge.core import mapping as mapping_module
from bridge.core.mapping import builtin_mapping_names
from bridge.mqtt import MqttPublishError

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "config.yaml"  # the five seed devices on the simulator
SITE = ROOT / "examples" / "site.yaml"  # a hardware site: RS-485 line and a gateway


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "bridge.cli", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=ROOT,
    )


def test_check_example_config_exits_0() -> None:
    result = run("check", "-c", str(EXAMPLE))
    assert result.returncode == 0, result.stderr
    assert "ok (1 bus(es), 5 device(s)" in result.stdout
    result = run("check", "-c", str(SITE))
    assert result.returncode == 0, result.stderr
    assert "ok (2 bus(es), 5 device(s)" in result.stdout


def test_check_says_a_sunspec_device_is_built_at_its_first_walk(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "config.yaml"
    config.write_text(
        "buses: [{id: lan, transport: tcp, host: 127.0.0.1}]\n"
        "devices: [{id: inverter, bus: lan, unit: 1, mapping: sunspec}]\n"
    )
    assert main(["check", "-c", str(config)]) == 0
    assert capsys.readouterr().out == (
        f"{config}: ok (1 bus(es), 1 device(s), 0 entities; "
        "1 SunSpec device(s) built at their first walk)\n"
    )
    assert not (tmp_path / "state").exists()  # a check writes nothing


def test_check_bad_config_exits_2_naming_the_field(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(SITE.read_text().replace("unit: 3", "unit: 0"))
    result = run("check", "-c", str(bad))
    assert result.returncode == 2
    assert f"{bad}: 1 error(s)" in result.stderr
    assert "devices.fan_drive.unit: Input should be greater than or equal to 1" in result.stderr
    assert result.stdout == ""


def test_schema_prints_both_json_schemas(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert set(document) == {"config", "mapping"}
    assert "devices" in document["config"]["properties"]
    assert "entities" in document["mapping"]["properties"]
    assert main(["schema", "mapping"]) == 0
    assert json.loads(capsys.readouterr().out)["title"] == "Mapping"


def test_mappings_list_names_all_shipped(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mappings", "list"]) == 0
    out = capsys.readouterr().out
    for name in ("nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100"):
        assert name in out
    assert len(out.splitlines()) == 1 + len(builtin_mapping_names())


def test_mappings_list_by_category(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mappings", "list", "--category", "drive"]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0].split() == ["NAME", "CATEGORY", "MANUFACTURER", "MODEL", "ENTITIES"]
    assert [row.split()[0] for row in rows[1:]] == ["p2_vfd", "vacon_nx"]
    assert all(row.split()[1] == "drive" for row in rows[1:])
    assert run("mappings", "list", "--category", "fridge").returncode == 2


def test_mappings_show_prints_the_index_entry_and_fingerprint(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["mappings", "show", "smartgen_hgm6100"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "category: genset" in out
    assert "transports: rtu" in out
    assert "aliases: HGM6110, HGM6120, HGM6110N, HGM6120N" in out
    assert any(line.startswith("document: SmartGen HGM6100 series") for line in out)
    assert out.index(next(line for line in out if line.startswith("fingerprint: "))) > next(
        i for i, line in enumerate(out) if line.startswith("KEY ")
    )
    assert any(line.startswith("  probe ") for line in out)


def test_mappings_show_prints_a_library_meters_disagreements(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["mappings", "show", "eastron_sdm630"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "category: meter" in out
    assert any(line.startswith("document: Eastron SDM630Modbus") and "V1.8" in line for line in out)
    assert any(line.startswith("disagreement frequency (openems): ") for line in out)
    row = next(line for line in out if line.startswith("current_l1 "))
    assert row.split()[:5] == ["current_l1", "0x0006", "6", "(0x0006)", "input"]


@pytest.mark.parametrize("ref", ["SDM630", "sdm-630", "SDM630-Modbus V2"])
def test_mappings_show_finds_a_model_by_an_alias(
    ref: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["mappings", "show", ref]) == 0
    assert capsys.readouterr().out.startswith("Eastron SDM630-Modbus V2: ")


def test_mappings_show_prints_printed_and_wire_address(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mappings", "show", "nastec_vasco"]) == 0
    line = next(
        row for row in capsys.readouterr().out.splitlines() if row.startswith("actual_value ")
    )
    assert "0x0098" in line
    assert "151 (0x0097)" in line


def test_mappings_show_option_and_bad_option(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mappings", "show", "smartgen_hgm6100", "-o", "model=hgm6110"]) == 0
    assert "option model = hgm6110" in capsys.readouterr().out
    assert main(["mappings", "show", "smartgen_hgm6100", "-o", "model=hgm9999"]) == 2
    assert "--option model=hgm9999: choose from" in capsys.readouterr().err


def test_mappings_validate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = ROOT / "mappings" / "soft_starter.yaml"
    bad = tmp_path / "bad.yaml"
    bad.write_text(good.read_text().replace("\nmanufacturer:", "\nmanufactuer:", 1))
    assert main(["mappings", "validate", str(good)]) == 0
    assert "soft_starter.yaml: ok" in capsys.readouterr().out
    assert main(["mappings", "validate", str(good), str(bad)]) == 2
    err = capsys.readouterr().err
    assert "manufacturer: Field required" in err
    assert "manufactuer: Extra inputs are not permitted" in err


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["--version"])
    assert caught.value.code == 0
    assert capsys.readouterr().out.startswith("modbus-mqtt-bridge ")


def test_a_reader_that_stops_early_is_no_error() -> None:
    """``schema | head``: the pipe closes before the schema is written; nothing on stderr."""
    with subprocess.Popen(
        [sys.executable, "-m", "bridge.cli", "schema"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=ROOT,
    ) as schema:
        assert schema.stdout is not None and schema.stderr is not None
        first = schema.stdout.readline()
        schema.stdout.close()  # what head does after its lines
        err = schema.stderr.read().decode()
        schema.wait(30)
    assert first.strip() == b"{"
    assert err == ""


@pytest.mark.parametrize("command", ["demo", "simulate", "run", "check", "scan", "read"])
def test_help_is_plain_text(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    """--help shows what a terminal can show: no reST markup from docstrings."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert "``" not in capsys.readouterr().out


def test_a_missing_mapping_file_is_named_where_it_was_looked_for(tmp_path: Path) -> None:
    """A config's mapping paths start at the config file's folder, whatever the current
    directory; the error names the file it tried."""
    site = tmp_path / "site"
    site.mkdir()
    config = site / "config.yaml"
    config.write_text(
        "buses: [{id: sim, transport: tcp, host: 127.0.0.1}]\n"
        "devices: [{id: oven, bus: sim, unit: 1, mapping: my_device.yaml}]\n"
    )
    result = run("check", "-c", str(config))  # run from the repository's folder
    assert result.returncode == 2
    assert f"and no file {site / 'my_device.yaml'}" in result.stderr
    (site / "my_device.yaml").write_text(
        (ROOT / "examples" / "mappings" / "temperature_controller.yaml").read_text()
    )
    assert run("check", "-c", str(config)).returncode == 0


def test_run_says_a_bridge_error_that_ended_it_in_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The bridge's TaskGroups wrap what ended it in (nested) ExceptionGroups: ``run``
    prints the bridge's own error as ``error: ...`` and exits 1, no traceback. Bridge.run
    stands in for a bridge that ended so (the thing under test is the command line)."""

    async def ended(_: Bridge) -> None:
        refused = MqttPublishError("cannot publish to x: too long")
        raise ExceptionGroup("bridge", [ExceptionGroup("session", [ValueError(), refused])])

    monkeypatch.setattr(Bridge, "run", ended)
    monkeypatch.setattr(cli, "configure_logging", lambda *_: None)  # pytest keeps its handlers
    assert main(["run", "-c", str(EXAMPLE)]) == 1
    assert capsys.readouterr().err == "error: cannot publish to x: too long\n"


USERS_OWN = """manufacturer: Unknown (OEM)
model: X1
description: a user's battery inverter, named as its owner reads it
source: {title: manual}
entities:
  bms_voltage: {name: BMS voltage, address: 1}
  dsp_temperature: {name: DSP temperature, address: 2}
  ems_mode: {name: EMS mode, address: 3}
  speed: {name: Motor SPEED, address: 4}
  baud: {name: Baud rate, address: 5, ha: {entity_category: diagnostic, enabled: true}}
"""
LIBRARY_ROWS = [
    "library: a shipped mapping has its index entry (docs/mappings.md, Library)",
    "manufacturer: 'Unknown (OEM)' does not read as a company's name (write 'Generic' when "
    "the manual names none, and what you know in a comment)",
    "entities.bms_voltage.name: 'BMS' is written in capitals: write it as a word, or add the "
    "abbreviation to bridge/core/convention.py ('BMS voltage')",
    "entities.dsp_temperature.name: 'DSP' is written in capitals: write it as a word, or add "
    "the abbreviation to bridge/core/convention.py ('DSP temperature')",
    "entities.ems_mode.name: 'EMS' is written in capitals: write it as a word, or add the "
    "abbreviation to bridge/core/convention.py ('EMS mode')",
    "entities.speed.name: 'SPEED' is written in capitals: write it as a word, or add the "
    "abbreviation to bridge/core/convention.py ('Motor SPEED')",
    "entities.baud.ha.enabled: a diagnostic entity is disabled by default: say why it is "
    "enabled in ha.enabled_reason",
]


def users_site(tmp_path: Path) -> Path:
    (tmp_path / "mine.yaml").write_text(USERS_OWN)
    config = tmp_path / "site.yaml"
    config.write_text(
        "mqtt: {url: 'mqtt://127.0.0.1:1'}\n"
        "buses: [{id: line, transport: tcp, host: 127.0.0.1, tcp_port: 1}]\n"
        "devices:\n"
        "  - {id: a, name: A, bus: line, unit: 1, mapping: mine.yaml}\n"
        "  - {id: b, name: B, bus: line, unit: 2, mapping: mine.yaml}\n"
    )
    return config


def test_a_users_names_are_the_users(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The library's naming rules are not a user's: "BMS voltage", a name in capitals, a
    placeholder manufacturer and an enabled diagnostic entity validate and check with no
    warning, and nothing sends the user to edit the package."""
    config = users_site(tmp_path)
    assert main(["mappings", "validate", str(tmp_path / "mine.yaml")]) == 0
    assert capsys.readouterr() == (f"{tmp_path / 'mine.yaml'}: ok (5 entities)\n", "")
    assert main(["check", "-c", str(config)]) == 0
    assert capsys.readouterr() == (
        f"{config}: ok (1 bus(es), 2 device(s), 10 entities)\n",
        "",
    )


def test_run_logs_no_advice_on_a_users_names(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    started: list[Bridge] = []

    async def starts(bridge: Bridge) -> None:
        started.append(bridge)

    config = users_site(tmp_path)
    monkeypatch.setattr(Bridge, "run", starts)
    monkeypatch.setattr(cli, "configure_logging", lambda *_: None)  # pytest keeps its handlers
    with caplog.at_level("DEBUG"):
        assert main(["run", "-c", str(config)]) == 0
    assert len(started) == 1
    assert [r for r in caplog.records if r.levelno >= logging.WARNING] == []
    assert not [r for r in caplog.records if "bridge/" in r.getMessage() or ".py" in r.getMessage()]


def test_the_library_rules_are_warned_of_for_a_file_of_the_library(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A file in the shipped mappings folder (a contributor's new mapping) is validated
    against the library's conventions; the same file elsewhere is not."""
    library = tmp_path / "mappings"
    library.mkdir()
    (library / "new_device.yaml").write_text(USERS_OWN)
    monkeypatch.setattr(mapping_module, "mappings_folder", library.resolve)
    assert main(["mappings", "validate", str(library / "new_device.yaml")]) == 0
    out, err = capsys.readouterr()
    assert out == f"{library / 'new_device.yaml'}: ok (5 entities, 7 warning(s))\n"
    assert err.splitlines() == [
        f"warning: {library / 'new_device.yaml'}: 7 warning(s)",
        *(f"  {row}" for row in LIBRARY_ROWS),
    ]
