"""``modbus-mqtt-bridge import ha``: the files it writes pass ``check``, name their source,
and never overwrite; the report goes to stderr; exit 2 only when nothing usable came out."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from bridge.app import Bridge
from bridge.cli import console, main
from bridge.config import load_config

CONFIG = """\
modbus:
  - name: Boiler
    type: tcp
    host: 127.0.0.1
    port: 5020
    delay: 90
    sensors:
      - {name: Water temperature, address: 3, slave: 2, scale: 0.1, precision: 1,
         unit_of_measurement: "°C", device_class: temperature, state_class: measurement}
    switches:
      - {name: Pump, address: 5, slave: 2, write_type: coil, verify: null}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "configuration.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_files_pass_check_and_name_their_source(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = write(tmp_path, CONFIG)
    out = tmp_path / "bridge"
    assert main(["import", "ha", str(source), "--out", str(out)]) == 0
    printed = capsys.readouterr()
    assert printed.err == (
        "configuration.yaml: 1 key(s) not converted or converted in part\n"
        "  configuration.yaml:6: Boiler.delay: partly converted: 90 s: the bus waits 60 s, "
        "its longest\n"
    )
    assert printed.out.startswith(f"{out / 'config.yaml'}: 1 device(s), 2 entities; 1 note(s)")
    header = f"# Imported by `modbus-mqtt-bridge import` from Home Assistant modbus {source}\n"
    for name in ("config.yaml", "mappings/boiler.yaml"):
        assert (out / name).read_text(encoding="utf-8").startswith(header)
    assert (out / "import-report.txt").read_text(encoding="utf-8") == printed.err
    assert main(["check", "-c", str(out / "config.yaml")]) == 0
    loaded = load_config(out / "config.yaml")
    assert loaded.config.buses[0].connect_delay == 60  # Home Assistant's hub delay
    pump = loaded.mappings["boiler"].entities["pump"]
    assert (pump.table.value, pump.access.value, pump.ha.entity_id) == ("coil", "rw", "pump")


def test_nothing_usable_exits_2_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = write(tmp_path, "modbus:\n  - {name: x, type: udp, host: h, port: 1}\n")
    out = tmp_path / "bridge"
    assert main(["import", "ha", str(source), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "configuration.yaml:2: x.type: not converted: the bridge has no UDP transport" in err
    assert f"error: {source}: nothing usable to import" in err
    assert not out.exists()


def test_existing_files_are_never_overwritten(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = write(tmp_path, CONFIG)
    out = tmp_path / "bridge"
    out.mkdir()
    (out / "config.yaml").write_text("mine\n", encoding="utf-8")
    assert main(["import", "ha", str(source), "--out", str(out)]) == 2
    assert "would overwrite config.yaml" in capsys.readouterr().err
    assert (out / "config.yaml").read_text(encoding="utf-8") == "mine\n"
    assert not (out / "mappings").exists()


def test_a_file_that_is_not_yaml_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = write(tmp_path, "modbus: [\n")
    assert main(["import", "ha", str(source), "--out", str(tmp_path / "o")]) == 2
    assert "invalid YAML" in capsys.readouterr().err


BATTERY = """\
modbus:
  - name: Battery inverter
    type: tcp
    host: 127.0.0.1
    port: 5020
    sensors:
      - {name: BMS voltage, address: 3, slave: 1, scale: 0.1, unit_of_measurement: V,
         device_class: voltage, state_class: measurement}
      - {name: DSP temperature, address: 4, slave: 1, unit_of_measurement: "°C",
         device_class: temperature}
      - {name: EMS mode, address: 5, slave: 1}
"""


@pytest.mark.parametrize("fixture", [None, "configuration.yaml", "configuration_2.yaml"])
def test_an_imported_mapping_loads_with_no_advice_to_edit_the_package(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
    fixture: str | None,
) -> None:
    """Names such as "BMS voltage" are the user's: importing, checking and starting the
    bridge on the imported files name no file of the package (Home Assistant's own test
    fixtures too)."""
    data = Path(__file__).parent / "data" / "ha_fixtures"
    text = BATTERY if fixture is None else (data / fixture).read_text(encoding="utf-8")
    source = write(tmp_path, text)
    out = tmp_path / "imported"
    monkeypatch.setattr(Bridge, "run", _returns)
    monkeypatch.setattr(console, "configure_logging", lambda *_: None)  # pytest's handlers
    with caplog.at_level("DEBUG"):
        assert main(["import", "ha", str(source), "--out", str(out)]) == 0
        assert main(["check", "-c", str(out / "config.yaml")]) == 0
        assert main(["mappings", "validate", *map(str, (out / "mappings").iterdir())]) == 0
        assert main(["run", "-c", str(out / "config.yaml")]) == 0
    said = [r.getMessage() for r in caplog.records] + capsys.readouterr().err.splitlines()
    assert [line for line in said if "bridge/" in line or ".py" in line] == []
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []


async def _returns(_: Bridge) -> None:
    """Bridge.run for a start that loaded its config (the thing under test is the load)."""
