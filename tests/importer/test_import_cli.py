"""``modbus-mqtt-bridge import ha``: the files it writes pass ``check``, name their source,
and never overwrite; the report goes to stderr; exit 2 only when nothing usable came out."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.cli import main
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
