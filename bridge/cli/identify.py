"""``modbus-mqtt-bridge identify``: what is at unit N (bridge/modbus/identify.py).

    modbus-mqtt-bridge identify --bus 'rtu:///dev/ttyUSB0?baudrate=9600' --unit 3
    modbus-mqtt-bridge identify --bus tcp://10.0.0.7 --units 1-247 --json

Read-only: a SunSpec marker, else the best matches of the shipped mappings' fingerprints
with a confidence, and the device entry to paste into the config. Exit codes: 0 a unit
answered, 2 invalid input (nothing sent), 1 the bus failed or no unit answered.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path
from typing import TextIO

from bridge.cli.bus_spec import FORMS, select_bus
from bridge.cli.commission import (
    EXIT_FAILED,
    EXIT_OK,
    Commands,
    _guarded,
    _print_json,
    _where,
    seconds,
    unit_id,
    unit_list,
)
from bridge.cli.lifecycle import until_stopped
from bridge.core.fingerprint import HIGH, LIKE_CAP, MEDIUM
from bridge.core.identify import Identity
from bridge.core.mapping import shipped_library
from bridge.modbus.commission import open_bus
from bridge.modbus.identify import identify, request_bound
from bridge.sunspec.walk import BASES

IDENTIFY_TIMEOUT = 0.2  # for a unit's first answer, like scan's


def add_parser(commands: Commands) -> None:
    """Register ``identify``."""
    bound = (
        f"1 + the larger of {request_bound({}) - 1} (a SunSpec walk) and {len(BASES)} + 4 "
        f"per mapping of the library ({request_bound(shipped_library())} with the shipped ones)"
    )
    parser = commands.add_parser(
        "identify",
        help="tell what device answers at a unit (read-only)",
        description="Read a few registers of each unit, never writing: the scan probe "
        "(holding 0; no answer within --timeout means no unit, one timeout spent; the "
        "reads after it wait the bus's timeout), the "
        f"SunSpec marker 'SunS' at holding {', '.join(map(str, BASES))} (where found, the "
        "model chain and the common model: manufacturer, model, serial, version), else "
        "each shipped mapping's fingerprint reads (only the function codes and read sizes "
        f"that mapping allows). At most {bound} requests per unit; a unit that leaves 2 "
        "reads unanswered is left. Confidence: "
        "(1 - product of (1 - weight) over the probes that matched) x (their share of "
        f"all weights); high from {HIGH}, medium from {MEDIUM}, low below; a mapping whose "
        f"manual names nothing identifying says 'answers like' and is scaled by {LIKE_CAP}.",
        epilog="exit codes: 0 a unit answered, 2 invalid input (nothing sent), 1 bus failure "
        "or no unit answered",
    )
    parser.add_argument(
        "--bus",
        required=True,
        metavar="SPEC_OR_ID",
        help=f"{' | '.join(FORMS)} (quote it); or the id of a bus in the -c config file",
    )
    parser.add_argument("-c", "--config", type=Path, metavar="FILE", help="config file of --bus")
    parser.add_argument("--json", action="store_true", help="print JSON for scripts")
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--unit", type=unit_id, metavar="N", help="one unit id")
    which.add_argument("--units", type=unit_list, metavar="LIST", help="e.g. 1-247 or 1,3,10-20")
    parser.add_argument(
        "--timeout",
        type=seconds,
        default=IDENTIFY_TIMEOUT,
        metavar="SECONDS",
        help=f"wait this long for each unit's first answer (default {IDENTIFY_TIMEOUT})",
    )
    parser.set_defaults(handler=_guarded(_identify))


def _identify(args: argparse.Namespace, out: TextIO) -> int:
    bus = select_bus(args.bus, args.config)
    units: tuple[int, ...] = (args.unit,) if args.unit is not None else args.units
    mappings = shipped_library()
    found: list[Identity] = []
    done: list[int] = []

    def heard(unit: int, identity: Identity | None) -> None:
        done.append(unit)
        if identity is not None:
            found.append(identity)
            print(f"unit {unit}: {identity.summary()}", file=sys.stderr)

    async def session() -> None:
        async with open_bus(bus) as submit:
            await identify(
                submit,
                units,
                mappings,
                args.timeout,
                bus.id,
                on_progress=heard,
                read_timeout=bus.timeout,
            )

    asyncio.run(until_stopped(session()))
    if len(done) != len(units):
        print(f"stopped after {len(done)} of {len(units)} units", file=sys.stderr)
    if args.json:
        document = {"bus": bus.id, "probed": done, "max_requests_per_unit": request_bound(mappings)}
        _print_json(document | {"found": [identity.as_dict() for identity in found]}, out)
    else:
        _print_found(found, out)
    if not found:
        print(f"no unit answered on {_where(bus)} (wiring, baud rate, parity?)", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _print_found(found: list[Identity], out: TextIO) -> None:
    for identity in found:
        print(f"unit {identity.unit}: {identity.summary()}", file=out)
        for match in identity.matches[1:]:
            print(f"  also: {match.describe()}", file=out)
        if identity.note:
            print(f"  ({identity.note})", file=out)
        document = identity.as_dict()
        if document["config"]:
            print("  config (paste under devices:):", file=out)
            for line in document["config"].splitlines():
                print(f"    {line}", file=out)
