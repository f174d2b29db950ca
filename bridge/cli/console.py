"""Command line: ``modbus-mqtt-bridge run | check | schema | mappings list|show|validate``;
the other commands' parsers come from their modules in ``bridge.cli`` (``_LAZY``).

Exit codes: 0 success, 2 invalid input (the message names file, entity or path, field).
"""

from __future__ import annotations

import argparse
import asyncio
import importlib
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from bridge import __version__
from bridge.cli.lifecycle import add_logging_arguments, configure_logging, until_stopped
from bridge.cli.mapping_view import named, print_fingerprint, print_header
from bridge.config import config_schema, load_config
from bridge.core.address import format_address
from bridge.core.entity import Entity
from bridge.core.library import Category
from bridge.core.mapping import (
    Mapping,
    check_mapping_file,
    in_library,
    library_index,
    load_mapping,
    mapping_schema,
    resolve_mapping_path,
    shipped_library,
)
from bridge.errors import BridgeError, InputError, MappingError, first_of

EXIT_OK = 0
EXIT_INVALID = 2
EXIT_FAILED = 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    arguments = sys.argv[1:] if argv is None else list(argv)
    try:
        args = _parser(_command_of(arguments)).parse_args(arguments)
        code = int(args.handler(args, sys.stdout))
        sys.stdout.flush()
    except BrokenPipeError:  # `schema | head`: the reader has seen enough
        return _reader_gone()
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except OSError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    return code


def _reader_gone() -> int:
    """stdout's reader closed the pipe: say nothing (Python's own advice: point stdout at
    devnull so the flush at exit cannot fail again) and exit 1."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    return EXIT_FAILED


# Subcommands whose modules load what ``run`` never needs (rich, the simulator, the
# embedded demo broker): their parsers are built only when one of them is asked for (or
# for help and errors, which list every command), so ``run`` keeps none of it in memory.
_LAZY = {  # command: (module, the function that adds its parser)
    "simulate": ("bridge.cli.simulate", "add_parser"),
    "scan": ("bridge.cli.commission", "add_parsers"),
    "read": ("bridge.cli.commission", "add_parsers"),
    "write": ("bridge.cli.commission", "add_parsers"),
    "identify": ("bridge.cli.identify", "add_parser"),
    "demo": ("bridge.cli.demo", "add_parser"),
    "import": ("bridge.cli.importer", "add_parser"),
}


def _command_of(arguments: Sequence[str]) -> str | None:
    return next((a for a in arguments if not a.startswith("-")), None)


def _parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line; with ``command`` given and not one of ``_LAZY``, without the
    lazy subcommands."""
    parser = argparse.ArgumentParser(
        prog="modbus-mqtt-bridge",
        description="Modbus RTU/TCP devices to MQTT and Home Assistant.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    check = commands.add_parser("check", help="validate a config file and its mappings")
    check.add_argument("-c", "--config", type=Path, required=True, metavar="FILE")
    check.set_defaults(handler=_check)

    schema = commands.add_parser("schema", help="print the JSON Schema of config and mapping")
    schema.add_argument("which", nargs="?", choices=("all", "config", "mapping"), default="all")
    schema.add_argument(
        "--markdown", action="store_true", help="print the config reference (docs/config.md)"
    )
    schema.set_defaults(handler=_schema)

    mappings = commands.add_parser("mappings", help="list, show or validate mappings")
    actions = mappings.add_subparsers(dest="action", required=True, metavar="ACTION")
    listed = actions.add_parser("list", help="the shipped mappings")
    listed.add_argument(
        "--category", choices=[c.value for c in Category], help="only this kind of device"
    )
    listed.set_defaults(handler=_list)
    show = actions.add_parser(
        "show", help="a mapping's index entry, entities with wire addresses, fingerprint"
    )
    show.add_argument(
        "name", help="shipped mapping name, its model or an alias (SDM630), or a YAML file"
    )
    show.add_argument(
        "-o",
        "--option",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="select a model option (repeatable)",
    )
    show.set_defaults(handler=_show)
    validate = actions.add_parser("validate", help="validate mapping files")
    validate.add_argument("files", nargs="+", type=Path, metavar="FILE")
    validate.set_defaults(handler=_validate)
    run = commands.add_parser("run", help="run the bridge: poll devices, publish to MQTT")
    run.add_argument("-c", "--config", type=Path, required=True, metavar="FILE")
    add_logging_arguments(run)
    run.set_defaults(handler=_run)
    eager = command is not None and command in _EAGER
    wanted = [] if eager else [_LAZY[command]] if command in _LAZY else list(_LAZY.values())
    for module, function in dict.fromkeys(wanted):
        getattr(importlib.import_module(module), function)(commands)
    return parser


_EAGER = ("check", "schema", "mappings", "run")


def _run(args: argparse.Namespace, _: TextIO) -> int:
    from bridge.app import Bridge  # noqa: PLC0415 - the MQTT stack loads only for `run`

    loaded = load_config(args.config)
    configure_logging(args.log_level, args.log_format)
    try:
        bridge = Bridge(loaded)
        asyncio.run(until_stopped(bridge.run(), hangup=bridge.hangup))
    except ExceptionGroup as failed:  # the bridge's task groups wrap what ended it
        reason = first_of(failed, BridgeError)
        if reason is None:
            raise
        print(f"error: {reason}", file=sys.stderr)
        return EXIT_INVALID if isinstance(reason, InputError) else EXIT_FAILED
    return EXIT_OK


def _check(args: argparse.Namespace, out: TextIO) -> int:
    loaded = load_config(args.config)
    config = loaded.config
    entities = sum(
        len(loaded.mappings[d.id].active(d.options)) for d in config.devices if d.enabled
    )
    pending = sum(1 for d in config.devices if d.enabled and not loaded.mappings[d.id].entities)
    walked = f"; {pending} SunSpec device(s) built at their first walk" if pending else ""
    print(
        f"{args.config}: ok ({len(config.buses)} bus(es), {len(config.devices)} device(s), "
        f"{entities} entities{walked})",
        file=out,
    )
    return EXIT_OK


def _schema(args: argparse.Namespace, out: TextIO) -> int:
    if args.markdown:
        from bridge.cli.config_doc import render_config_doc  # noqa: PLC0415 - docs only

        out.write(render_config_doc())
        return EXIT_OK
    schemas = {"config": config_schema(), "mapping": mapping_schema()}
    document = schemas if args.which == "all" else schemas[args.which]
    json.dump(document, out, indent=2)
    out.write("\n")
    return EXIT_OK


def _list(args: argparse.Namespace, out: TextIO) -> int:
    rows = []
    for name, mapping in shipped_library().items():
        category = mapping.library.category.value if mapping.library is not None else ""
        if args.category in (None, category):
            size = str(len(mapping.entities))
            rows.append((name, category, mapping.manufacturer, mapping.model, size))
    _table(("NAME", "CATEGORY", "MANUFACTURER", "MODEL", "ENTITIES"), rows, out)
    return EXIT_OK


def _show(args: argparse.Namespace, out: TextIO) -> int:
    ref = args.name
    if ref not in library_index() and not Path(ref).is_file():
        ref = named(ref) or ref  # a model or an alias: SDM630
    mapping = load_mapping(resolve_mapping_path(ref, Path.cwd()))
    options = _parse_options(args.option, mapping)
    print_header(mapping, out)
    for name, spec in mapping.options.items():
        chosen = options.get(name, spec.default)
        print(
            f"option {name} = {chosen}  ({', '.join(spec.choices)}): {spec.description}", file=out
        )
    rows: list[tuple[str, ...]] = []
    rule = mapping.protocol.addressing
    for key, point in mapping.points(options).items():
        e = point.entity
        unit = e.unit or (f"<{e.unit_from}>" if e.unit_from else "")
        wire = f"{point.address} (0x{point.address:04X})"
        address = format_address(e.address, rule)
        kind = (e.table.value, e.data_type.value, _bits(e), e.access.value)
        rows.append((key, address, wire, *kind, unit, e.component.value))
    headers = ("KEY", "PRINTED", "WIRE", "TABLE", "TYPE", "BITS", "ACCESS", "UNIT", "HA")
    _table(headers, rows, out)
    print_fingerprint(mapping, out)
    return EXIT_OK


def _bits(entity: Entity) -> str:
    if entity.bit is None:
        return ""
    last = entity.bit + (entity.field_width or 1) - 1
    return str(entity.bit) if last == entity.bit else f"{entity.bit}-{last}"


def _parse_options(pairs: list[str], mapping: Mapping) -> dict[str, str]:
    options: dict[str, str] = {}
    problems = []
    for pair in pairs:
        name, _, value = pair.partition("=")
        spec = mapping.options.get(name)
        if spec is None or value not in spec.choices:
            known = {n: list(s.choices) for n, s in mapping.options.items()}
            problems.append(f"--option {pair}: choose from {known}")
        options[name] = value
    if problems:
        raise InputError("options", problems)
    return options


def _validate(args: argparse.Namespace, out: TextIO) -> int:
    """Every error of each file, and for a file of the shipped library the warnings of its
    conventions (names, enabled defaults); exit 2 when a file has errors."""
    failed = 0
    for path in args.files:
        report = check_mapping_file(path, library=in_library(path))
        if report.mapping is None:
            print(f"error: {MappingError(report.source, list(report.errors))}", file=sys.stderr)
            failed += 1
        _print_warnings(report.source, report.warnings)
        if report.mapping is not None:
            warned = f", {len(report.warnings)} warning(s)" if report.warnings else ""
            print(f"{path}: ok ({len(report.mapping.entities)} entities{warned})", file=out)
    return EXIT_INVALID if failed else EXIT_OK


def _print_warnings(source: str, rows: Sequence[str]) -> None:
    if rows:
        lines = "".join(f"\n  {row}" for row in rows)
        print(f"warning: {source}: {len(rows)} warning(s){lines}", file=sys.stderr)


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]], out: TextIO) -> None:
    widths = [max(len(str(c)) for c in column) for column in zip(headers, *rows, strict=False)]
    for row in (headers, *rows):
        print(
            "  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)).rstrip(), file=out
        )
