"""``modbus-mqtt-bridge scan | read | write``: commissioning a bus without the bridge.

    modbus-mqtt-bridge scan --bus "rtu:///dev/ttyUSB0?baudrate=19200&parity=E" --units 1-20
    modbus-mqtt-bridge read --bus tcp://10.0.0.7 --unit 3 0x97 2
    modbus-mqtt-bridge write -c config.yaml --bus rs485 --unit 3 0x97 100

``--bus`` is a spec (``bridge/cli/bus_spec.py``) or, with ``-c``, the id of a bus in a config
file. Addresses are wire addresses (0-based, as in the frame), decimal or 0x hex. Results
go to stdout (``--json`` for scripts), progress and errors to stderr. Exit codes: 0 done,
2 invalid input (nothing sent), 1 the bus or the unit failed (or a scan found nobody).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Any, TextIO, TypeAlias, TypeVar

from rich import box
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table as RichTable

from bridge.cli.bus_spec import FORMS, select_bus
from bridge.cli.lifecycle import until_stopped
from bridge.config import SerialBus, TcpBus, load_config
from bridge.core.entity import Table
from bridge.core.interpret import ORDERS
from bridge.errors import ModbusError, ValueRejectedError
from bridge.modbus.commission import (
    COIL_ON,
    UNITS,
    Found,
    Submit,
    explain,
    open_bus,
    raw_read,
    raw_write,
    read_interpreted,
    scan,
)

EXIT_OK, EXIT_FAILED, EXIT_INVALID = 0, 1, 2
SCAN_TIMEOUT = 0.2
WIRE = "wire address (0-based, as sent in the frame), decimal or 0x hex"
Handler = Callable[[argparse.Namespace, TextIO], int]
Commands: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"
T = TypeVar("T")


def add_parsers(commands: Commands) -> None:
    """Register ``scan``, ``read`` and ``write``."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--bus",
        required=True,
        metavar="SPEC_OR_ID",
        help=f"{' | '.join(FORMS)} (quote it: '&' means something to the shell); "
        "or the id of a bus in the -c config file",
    )
    common.add_argument("-c", "--config", type=Path, metavar="FILE", help="config file of --bus")
    common.add_argument("--json", action="store_true", help="print JSON for scripts")
    _add_scan(commands, common)
    _add_read(commands, common)
    _add_write(commands, common)


_EPILOG = "exit codes: 0 done, 2 invalid input (nothing sent), 1 bus or unit failure"


def _add_scan(commands: Commands, common: argparse.ArgumentParser) -> None:
    scanner = commands.add_parser(
        "scan",
        parents=[common],
        help="find the units that answer on a bus",
        description="Probe each unit (read holding 0) one after the other. Any answer, even "
        "a Modbus exception, means a unit is there; no answer within --timeout means none.",
        epilog=_EPILOG,
    )
    scanner.add_argument(
        "--units",
        type=unit_list,
        default="1-247",
        metavar="LIST",
        help="e.g. 1-247 (default) or 1,3,10-20",
    )
    scanner.add_argument(
        "--timeout",
        type=seconds,
        default=SCAN_TIMEOUT,
        metavar="SECONDS",
        help=f"wait this long for each unit (default {SCAN_TIMEOUT})",
    )
    scanner.set_defaults(handler=_guarded(_scan))


def _add_read(commands: Commands, common: argparse.ArgumentParser) -> None:
    reader = commands.add_parser(
        "read",
        parents=[common],
        help="read raw registers or bits, shown every way",
        description="Read COUNT registers (or bits) from ADDRESS and show each word as u16, "
        "s16, hex, ASCII and bits, and each pair of words as u32/s32/f32 in the byte orders "
        f"ABCD, CDAB, BADC, DCBA. ADDRESS is a {WIRE}.",
        epilog=_EPILOG,
    )
    _add_target(reader, tuple(table.value for table in Table))
    reader.add_argument(
        "count", type=number, nargs="?", default=1, metavar="COUNT", help="registers or bits"
    )
    reader.set_defaults(handler=_guarded(_read))


def _add_write(commands: Commands, common: argparse.ArgumentParser) -> None:
    writer = commands.add_parser(
        "write",
        parents=[common],
        help="write raw registers or coils",
        description="Write VALUEs from ADDRESS: FC06 (coils FC05) for one value, FC16 (FC15) "
        f"for several. ADDRESS is a {WIRE}. Values are checked before anything is sent.",
        epilog=_EPILOG,
    )
    _add_target(writer, (Table.HOLDING.value, Table.COIL.value))
    writer.add_argument(
        "values", type=number, nargs="+", metavar="VALUE", help="0..65535 (coils: 0 or 1)"
    )
    writer.add_argument(
        "--function",
        type=int,
        choices=(5, 6, 15, 16),
        help="force a function code, e.g. 16 for one register on devices without FC06",
    )
    writer.add_argument(
        "--coil-on",
        type=number,
        default=COIL_ON,
        metavar="WORD",
        help="the word FC05 sends for ON (default 0xFF00; some devices want 0x00FF)",
    )
    writer.set_defaults(handler=_guarded(_write))


def _add_target(parser: argparse.ArgumentParser, tables: tuple[str, ...]) -> None:
    parser.add_argument("--unit", type=unit_id, required=True, metavar="N", help="unit id")
    parser.add_argument("--table", choices=tables, default="holding")
    parser.add_argument(
        "--timeout",
        type=seconds,
        metavar="SECONDS",
        help="wait this long for the answer (default: the bus's timeout)",
    )
    parser.add_argument("address", type=number, metavar="ADDRESS", help=WIRE)


# --- argument types ------------------------------------------------------------------


def number(text: str) -> int:
    """Decimal or 0x hex (``151``, ``0x97``)."""
    try:
        return int(text, 16) if text.lower().startswith("0x") else int(text, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a decimal or 0x hex number") from None


def unit_id(text: str) -> int:
    unit = number(text)
    if unit not in UNITS:
        raise argparse.ArgumentTypeError(f"unit {unit}: use 1..255 (0 is broadcast)")
    return unit


def unit_list(text: str) -> tuple[int, ...]:
    """``1-247``, ``1,3,10-20``: units in the order given, each once."""
    units: dict[int, None] = {}
    for part in text.split(","):
        first, sep, last = part.strip().partition("-")
        low = unit_id(first)
        high = unit_id(last) if sep else low
        if high < low:
            raise argparse.ArgumentTypeError(f"{part!r}: write ranges low-high")
        units |= dict.fromkeys(range(low, high + 1))
    return tuple(units)


def seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 < value <= 60:
        raise argparse.ArgumentTypeError(f"{text!r}: give seconds, more than 0 and at most 60")
    return value


# --- commands -------------------------------------------------------------------------


def _guarded(handler: Handler) -> Handler:
    """Refused input exits 2, a bus or unit failure exits 1, both with one clear line."""

    def guarded(args: argparse.Namespace, out: TextIO) -> int:
        try:
            return handler(args, out)
        except ValueRejectedError as exc:
            print(f"error: {exc} (nothing sent)", file=sys.stderr)
            return EXIT_INVALID
        except ModbusError as exc:
            print(f"error: {explain(getattr(args, 'unit', 0), exc)}", file=sys.stderr)
            return EXIT_FAILED

    return guarded


def _scan(args: argparse.Namespace, out: TextIO) -> int:
    bus = select_bus(args.bus, args.config)
    units: tuple[int, ...] = args.units
    found: list[Found] = []
    done: list[int] = []
    asyncio.run(until_stopped(_scan_showing_progress(bus, units, args.timeout, found, done)))
    complete = len(done) == len(units)
    if not complete:
        print(f"stopped after {len(done)} of {len(units)} units", file=sys.stderr)
    if args.json:
        document = {"bus": bus.id, "scanned": done, "complete": complete}
        _print_json(document | {"found": [f.as_dict() for f in found]}, out)
    elif found:
        _print_found(found, out)
    if not found:
        print(f"no unit answered on {_where(bus)} (wiring, baud rate, parity?)", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


async def _scan_showing_progress(
    bus: SerialBus | TcpBus,
    units: tuple[int, ...],
    timeout: float,
    found: list[Found],
    done: list[int],
) -> None:
    """Scan with a progress bar on stderr, once the bus is open; ``found`` and ``done``
    fill as units answer, so an interrupted scan keeps what it learned. On a terminal the
    bar counts the units found and what they answered is printed once, in the table at the
    end; when the results go elsewhere (a file, ``--json`` to a script), each unit found
    is also a line on stderr as it answers."""
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn())
    echo = not (sys.stdout.isatty() and sys.stderr.isatty())
    async with open_bus(bus) as submit:
        with Progress(*columns, TimeRemainingColumn(), console=Console(stderr=True)) as progress:
            task = progress.add_task(f"scanning {_where(bus)}", total=len(units))

            def heard(unit: int, result: Found | None) -> None:
                done.append(unit)
                if result is not None:
                    found.append(result)
                    if echo:
                        progress.console.print(f"unit {unit}: {result.describe()}", highlight=False)
                progress.update(
                    task,
                    advance=1,
                    description=f"scanning {_where(bus)}: unit {unit}, {len(found)} found",
                )

            await scan(submit, units, timeout, heard)


def _read(args: argparse.Namespace, out: TextIO) -> int:
    request = raw_read(args.table, args.address, args.count)  # checked before the bus opens
    bus = select_bus(args.bus, args.config)
    timeout = args.timeout or bus.timeout
    limit = _configured_limit(args.config, bus.id, args.unit, request.table)

    async def work(submit: Submit) -> dict[str, Any]:
        return await read_interpreted(submit, args.unit, request, timeout, limit=limit)

    reading = _run(bus, work)
    if reading["note"] and not args.json:
        print(f"unit {args.unit}: {reading['note']}", file=sys.stderr)
    if args.json:
        _print_json(reading, out)
    elif request.table.is_bits:
        _print_bits(reading, out)
    else:
        _print_registers(reading, out)
    return EXIT_OK


def _configured_limit(config: Path | None, bus_id: str, unit: int, table: Table) -> int | None:
    """The read limit of the device the config puts at ``unit`` on that bus (its mapping,
    with the device's protocol overrides), or None when there is none."""
    if config is None:
        return None
    loaded = load_config(config)
    for device in loaded.config.devices:
        if device.bus == bus_id and device.unit == unit and device.id in loaded.mappings:
            protocol = loaded.mappings[device.id].protocol
            if table.is_bits:
                return device.protocol.max_read_bits or protocol.max_read_bits
            return device.protocol.max_read_registers or protocol.max_read_registers
    return None


def _write(args: argparse.Namespace, out: TextIO) -> int:
    request = raw_write(
        args.table, args.address, args.values, function=args.function, coil_on_value=args.coil_on
    )
    bus = select_bus(args.bus, args.config)
    timeout = args.timeout or bus.timeout

    async def work(submit: Submit) -> tuple[int, ...]:
        return await submit(args.unit, request, timeout)

    _run(bus, work)
    if args.json:
        fields = ("function", "table", "address", "values")
        written = {name: getattr(request, name) for name in fields}
        _print_json({"unit": args.unit, **written, "values": list(request.values)}, out)
    else:
        values = " ".join(f"0x{v:04X} ({v})" for v in request.values)
        print(
            f"unit {args.unit}: wrote {values} to {request.table.value} {_address(request.address)}"
            f" with FC{request.function:02d}",
            file=out,
        )
    return EXIT_OK


def _run(bus: SerialBus | TcpBus, work: Callable[[Submit], Awaitable[T]]) -> T:
    """Open the bus, do the work, close; Ctrl-C ends it with exit code 1."""
    results: list[T] = []

    async def session() -> None:
        async with open_bus(bus) as submit:
            results.append(await work(submit))

    asyncio.run(until_stopped(session()))
    if not results:
        print("interrupted", file=sys.stderr)
        raise SystemExit(EXIT_FAILED)
    return results[0]


# --- output ---------------------------------------------------------------------------


def _console(out: TextIO) -> Console:
    return Console(file=out, highlight=False, soft_wrap=True)


def _print_json(document: object, out: TextIO) -> None:
    json.dump(document, out, indent=2)
    out.write("\n")


def _print_found(found: Sequence[Found], out: TextIO) -> None:
    table = RichTable("UNIT", "ANSWER", "LATENCY", box=box.SIMPLE_HEAD)
    for item in found:
        table.add_row(str(item.unit), item.describe(), f"{item.latency * 1000:.0f} ms")
    _console(out).print(table)


def _print_registers(reading: dict[str, Any], out: TextIO) -> None:
    console = _console(out)
    words = RichTable("ADDRESS", "HEX", "U16", "S16", "ASCII", "BITS", box=box.SIMPLE_HEAD)
    for word in reading["words"]:
        row = (_address(word["address"]), word["hex"], str(word["u16"]), str(word["s16"]))
        words.add_row(*row, repr(word["ascii"]), word["bits"])
    console.print(f"unit {reading['unit']} {reading['table']} registers")
    console.print(words)
    if not reading["pairs"]:
        return
    pairs = RichTable("ADDRESS", "ORDER", "U32", "S32", "F32", box=box.SIMPLE_HEAD)
    for pair in reading["pairs"]:
        for order in ORDERS:
            values = pair[order]
            pairs.add_row(
                _address(pair["address"]) if order == "ABCD" else "",
                order,
                str(values["u32"]),
                str(values["s32"]),
                str(values["f32"]),
            )
    console.print("pairs (ABCD big-endian, CDAB word swap, BADC byte swap, DCBA both)")
    console.print(pairs)


def _print_bits(reading: dict[str, Any], out: TextIO) -> None:
    table = RichTable("ADDRESS", "VALUE", box=box.SIMPLE_HEAD)
    for offset, bit in enumerate(reading["bits"]):
        table.add_row(_address(reading["address"] + offset), "ON (1)" if bit else "off (0)")
    console = _console(out)
    console.print(f"unit {reading['unit']} {reading['table']}")
    console.print(table)


def _address(address: int) -> str:
    return f"{address} (0x{address:04X})"


def _where(bus: SerialBus | TcpBus) -> str:
    if isinstance(bus, SerialBus):
        return f"{bus.port} {bus.transport} {bus.baudrate} {bus.bytesize}{bus.parity}{bus.stopbits}"
    return f"{bus.transport}://{bus.host}:{bus.tcp_port}"
