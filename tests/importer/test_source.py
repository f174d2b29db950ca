"""Reading a file to import: lines kept, !secret and !include resolved inside the file's
folder only, other tags reported, sizes bounded."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.importer import source
from bridge.importer.ha_modbus import import_ha
from bridge.importer.source import Node, SourceError, Unresolved, load_source


def test_keys_know_their_file_and_line(tmp_path: Path) -> None:
    (tmp_path / "c.yaml").write_text("a: 1\nb:\n  c: 2\n", encoding="utf-8")
    data = load_source(tmp_path / "c.yaml")
    assert isinstance(data, Node)
    assert (str(data.at("a")), str(data.at("b")), str(data["b"].at("c"))) == (
        "c.yaml:1",
        "c.yaml:2",
        "c.yaml:3",
    )


def test_secret_and_include_are_resolved_relative_to_the_file(tmp_path: Path) -> None:
    (tmp_path / "secrets.yaml").write_text("inverter_ip: 192.0.2.9\n", encoding="utf-8")
    (tmp_path / "modbus").mkdir()
    (tmp_path / "modbus" / "inverter.yaml").write_text(
        "- name: inv\n  type: tcp\n  host: !secret inverter_ip\n  port: 502\n"
        "  sensors:\n    - {name: Power, address: 1, slave: 1}\n",
        encoding="utf-8",
    )
    (tmp_path / "configuration.yaml").write_text(
        "modbus: !include modbus/inverter.yaml\n", encoding="utf-8"
    )
    result = import_ha(load_source(tmp_path / "configuration.yaml"), "configuration.yaml")
    assert result.buses[0]["host"] == "192.0.2.9"
    assert result.notes == []
    power = result.devices[0].mapping["entities"]["power"]
    assert power["address"] == 1


def test_an_include_outside_the_folder_or_an_unknown_tag_is_reported(tmp_path: Path) -> None:
    (tmp_path / "outside.yaml").write_text("x: 1\n", encoding="utf-8")
    inner = tmp_path / "ha"
    inner.mkdir()
    (inner / "configuration.yaml").write_text(
        "modbus:\n  - !include ../outside.yaml\n  - !include_dir_list hubs\n"
        "  - name: h\n    type: tcp\n    host: !env_var HOST\n    port: 502\n",
        encoding="utf-8",
    )
    data = load_source(inner / "configuration.yaml")
    first, second = data["modbus"][0], data["modbus"][1]
    assert isinstance(first, Unresolved) and first.reason.startswith("outside ")
    assert isinstance(second, Unresolved) and second.tag == "!include_dir_list"
    result = import_ha(data, "configuration.yaml")
    assert [(n.where.line, n.key) for n in result.notes] == [
        (2, "!include ../outside.yaml"),
        (3, "!include_dir_list hubs"),
        (6, "h.host"),
    ]
    assert not result.usable


def test_a_file_too_large_or_an_include_loop_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "loop.yaml").write_text("a: !include loop.yaml\n", encoding="utf-8")
    data = load_source(tmp_path / "loop.yaml")
    for _ in range(source.MAX_INCLUDE_DEPTH):
        data = data["a"]
    assert isinstance(data["a"], Unresolved) and "levels deep" in data["a"].reason
    monkeypatch.setattr(source, "MAX_FILE_BYTES", 10)
    with pytest.raises(SourceError, match="more than 10"):
        load_source(tmp_path / "loop.yaml")


def test_python_tags_are_not_constructed(tmp_path: Path) -> None:
    (tmp_path / "c.yaml").write_text("a: !!python/object/apply:os.system [ls]\n", encoding="utf-8")
    with pytest.raises(SourceError, match="invalid YAML"):
        load_source(tmp_path / "c.yaml")
