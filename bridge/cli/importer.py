"""``modbus-mqtt-bridge import ha|esphome FILE [--out DIR]``: another tool's Modbus YAML
as a bridge config and mappings, with a report of every key left out.

Writes ``DIR/config.yaml``, ``DIR/mappings/<device>.yaml`` and ``DIR/import-report.txt``
(never over an existing file), then checks them the way ``check`` does. Exit 0 when a
device with at least one entity came out (the report lists what did not), 2 when nothing
usable did or the files exist already.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, TextIO

import yaml

from bridge.config import load_config
from bridge.importer.esphome import import_esphome
from bridge.importer.esphome_check import check_node
from bridge.importer.ha_modbus import import_ha
from bridge.importer.result import Import
from bridge.importer.source import SourceError, load_source

EXIT_OK = 0
EXIT_INVALID = 2
_IMPORTERS = {"ha": import_ha, "esphome": import_esphome}
_TOOLS = {"ha": "Home Assistant modbus", "esphome": "ESPHome modbus_controller"}


def add_parser(commands: Any) -> None:
    """The ``import`` subcommand."""
    parser = commands.add_parser(
        "import", help="convert Home Assistant modbus or ESPHome YAML to a config and mappings"
    )
    parser.add_argument("tool", choices=tuple(_IMPORTERS), help="whose YAML FILE is")
    parser.add_argument("file", type=Path, metavar="FILE")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("imported"),
        metavar="DIR",
        help="folder for config.yaml, mappings/ and import-report.txt (default: imported)",
    )
    parser.add_argument(
        "--root",
        type=Path,
        default=None,
        metavar="DIR",
        help="folder !include and !secret may read from (default: FILE's folder)",
    )
    parser.set_defaults(handler=run_import)


def run_import(args: argparse.Namespace, out: TextIO) -> int:
    """Convert, write, check, report."""
    try:
        data = load_source(args.file, args.root)
    except SourceError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    result = _IMPORTERS[args.tool](data, args.file.name)
    if args.tool == "esphome":
        check_node(args.file, data, result)  # ESPHome's own validation, when installed
    report = render_report(result)
    sys.stderr.write(report)
    if not result.usable:
        print(f"error: {args.file}: nothing usable to import", file=sys.stderr)
        return EXIT_INVALID
    files = render_files(result, f"{_TOOLS[args.tool]} {args.file.resolve()}")
    files["import-report.txt"] = report
    taken = [name for name in files if (args.out / name).exists()]
    if taken:
        print(f"error: {args.out}: would overwrite {', '.join(taken)}", file=sys.stderr)
        return EXIT_INVALID
    for name, text in files.items():
        (args.out / name).parent.mkdir(parents=True, exist_ok=True)
        (args.out / name).write_text(text, encoding="utf-8")
    loaded = load_config(args.out / "config.yaml")
    print(
        f"{args.out / 'config.yaml'}: {len(loaded.config.devices)} device(s), "
        f"{sum(len(m.entities) for m in loaded.mappings.values())} entities; "
        f"{len(result.notes)} note(s) in {args.out / 'import-report.txt'}",
        file=out,
    )
    return EXIT_OK


def render_files(result: Import, source: str) -> dict[str, str]:
    """The config and mapping files' texts by path, each headed by its source."""
    header = f"# Imported by `modbus-mqtt-bridge import` from {source}\n"
    refs = {device.id: f"mappings/{device.id}.yaml" for device in result.devices}
    files = {"config.yaml": header + _dump(result.config(refs))}
    for device in result.devices:
        files[refs[device.id]] = header + _dump(device.mapping)
    return files


def render_report(result: Import) -> str:
    """Every note, one a line, under a count."""
    rows = "".join(f"  {note}\n" for note in result.notes)
    return f"{result.source}: {len(result.notes)} key(s) not converted or converted in part\n{rows}"


_SafeDumper: type[yaml.SafeDumper] = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _Dumper(_SafeDumper):  # type: ignore[valid-type,misc]
    """libyaml's safe dumper (when PyYAML has it: the files of 10,000 entities in a
    fraction of the time), writing every value out, never as an ``&anchor``/``*alias``."""

    def ignore_aliases(self, data: Any) -> bool:  # noqa: ARG002 - PyYAML's signature
        return True


def _dump(document: dict[str, Any]) -> str:
    return yaml.dump(document, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)
