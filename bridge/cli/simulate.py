"""``modbus-mqtt-bridge simulate``: serve simulated devices built from mappings.

    modbus-mqtt-bridge simulate --mapping nastec_vasco --unit 1 \
        --mapping soft_starter --unit 2 --tcp 127.0.0.1:5020
    modbus-mqtt-bridge simulate --mapping p2_vfd --unit 1 --pty --framer ascii
    modbus-mqtt-bridge simulate --sunspec 3=inverter.json@40000 --tcp 127.0.0.1:5020

``--pty`` creates a virtual serial cable and prints the port the bridge should open.
Quirks (``--latency``, ``--dead``, ``--max-read``...) reproduce real devices' behaviour.
The devices follow their commands; ``--fault KEY[=LABEL]`` starts them tripped;
``--counter-fault energy=tear@60`` makes a counter misread a minute after the start.
``--sunspec UNIT=IMAGE.json[@BASE]`` serves a SunSpec device from a device image
(pysunspec2's JSON: its models and point values), its marker at BASE (default 40000).
"""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path
from typing import TextIO

from bridge.cli.lifecycle import until_stopped
from bridge.core.mapping import Mapping, load_mapping, resolve_mapping_path
from bridge.errors import InputError, ValueRejectedError
from bridge.modbus.null_modem import null_modem
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator, SunSpecUnit
from bridge.sunspec.image import DeviceImageError, load_image


def add_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    sim = commands.add_parser("simulate", help="serve simulated devices built from mappings")
    sim.add_argument(
        "--mapping",
        action="append",
        default=[],
        metavar="NAME",
        help="shipped mapping name or YAML path (repeat with --unit)",
    )
    sim.add_argument(
        "--unit",
        action="append",
        default=[],
        type=int,
        metavar="N",
        help="unit id of the preceding --mapping",
    )
    sim.add_argument(
        "--sunspec",
        action="append",
        default=[],
        metavar="UNIT=IMAGE[@BASE]",
        help="a SunSpec device at UNIT from a device image (pysunspec2's JSON), its marker "
        "at BASE (default 40000; repeatable)",
    )
    sim.add_argument(
        "-o",
        "--option",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a mapping option for every unit that has it",
    )
    where = sim.add_mutually_exclusive_group(required=True)
    where.add_argument("--tcp", metavar="HOST:PORT", help="serve Modbus TCP (or RTU over TCP)")
    where.add_argument("--serial", metavar="PORT", help="serve a serial port")
    where.add_argument("--pty", action="store_true", help="create a virtual serial cable")
    sim.add_argument(
        "--framer", choices=("socket", "rtu", "ascii"), help="default: socket on TCP, rtu on serial"
    )
    sim.add_argument("--baudrate", type=int, default=9600)
    sim.add_argument("--parity", choices=("N", "E", "O"), default="N")
    sim.add_argument("--stopbits", type=int, choices=(1, 2), default=1)
    sim.add_argument("--tick", type=float, default=1.0, help="seconds between value changes")
    sim.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="KEY[=LABEL]",
        help="start tripped: this alarm on (a fault code's LABEL) in every unit that has it; "
        "the device's fault reset clears it (repeatable)",
    )
    sim.add_argument(
        "--counter-fault",
        action="append",
        default=[],
        metavar="KEY=FAULT[@SECONDS]",
        help="counter KEY misreads SECONDS after the start (default 30) in every unit that "
        "has it: zero, reboot (0 for two reads), tear, jitter (-1 digit), wrap, reset "
        "(repeatable)",
    )
    sim.add_argument("--seed", type=int, default=0)
    quirks = sim.add_argument_group("device quirks (every unit)")
    quirks.add_argument("--latency", type=float, default=0.0, help="seconds before each answer")
    quirks.add_argument(
        "--dead",
        action="append",
        type=int,
        default=[],
        metavar="UNIT",
        help="this unit never answers",
    )
    quirks.add_argument("--max-read", type=int, metavar="N", help="refuse longer reads")
    quirks.add_argument(
        "--refuse-gaps",
        action="store_true",
        help="refuse reads of addresses the mapping does not define",
    )
    quirks.add_argument(
        "--coil-on-value",
        type=lambda text: int(text, 0),
        metavar="WORD",
        help="FC05 ON word the device accepts (0xFF00 or 0x00FF)",
    )
    quirks.add_argument(
        "--exception",
        type=int,
        metavar="CODE",
        help="answer every request with this exception code",
    )
    quirks.add_argument(
        "--two-byte-count",
        action="store_true",
        help="FC03 replies with a 2-byte byte count (P2 with F9.05 = 0)",
    )
    quirks.add_argument(
        "--locked",
        type=int,
        metavar="PASSWORD",
        help="locked by this user password until it is written to the unlock register "
        "(a mapping with protocol.unlock: the P2)",
    )
    sim.set_defaults(handler=run_simulate)


def build_simulator(args: argparse.Namespace) -> Simulator:
    """The simulator the arguments describe; InputError naming the bad argument."""
    if len(args.mapping) != len(args.unit):
        raise InputError("simulate", ["give one --unit after each --mapping"])
    if not args.mapping and not args.sunspec:
        raise InputError("simulate", ["give at least one --mapping (with --unit) or --sunspec"])
    options = dict(pair.partition("=")[::2] for pair in args.option)
    mappings = [load_mapping(resolve_mapping_path(ref)) for ref in args.mapping]
    problems = _option_problems(options, mappings)
    if problems:
        raise InputError("simulate", problems)
    units = []
    for mapping, unit in zip(mappings, args.unit, strict=True):
        mine = {k: v for k, v in options.items() if k in mapping.options}
        quirks = Quirks(
            max_read_registers=args.max_read,
            refuse_gaps=True if args.refuse_gaps else None,
            coil_on_value=args.coil_on_value,
            exception_code=args.exception,
            latency=args.latency,
            dead=unit in args.dead,
            two_byte_count=args.two_byte_count,
            password=args.locked if mapping.protocol.unlock is not None else None,
        )
        units.append(SimulatedUnit(unit, mapping, mine, quirks))
    try:
        simulator = Simulator(
            [*units, *_sunspec_units(args.sunspec)], seed=args.seed, tick=args.tick
        )
    except ValueError as exc:
        raise InputError("simulate", [str(exc)]) from None
    _trip(simulator, [(spec.unit, spec.mapping) for spec in units], args.fault)
    _counter_faults(simulator, units, args.counter_fault)
    return simulator


def _sunspec_units(specs: list[str]) -> list[SunSpecUnit]:
    """``--sunspec UNIT=IMAGE[@BASE]``: each image laid out (InputError names the bad one)."""
    units, problems = [], []
    for spec in specs:
        unit, _, rest = spec.partition("=")
        path, _, base = rest.partition("@")
        try:
            units.append(SunSpecUnit(int(unit), load_image(Path(path), int(base or 40000))))
        except ValueError as exc:  # DeviceImageError too
            reason = exc if isinstance(exc, DeviceImageError) else "UNIT and BASE are numbers"
            problems.append(f"--sunspec {spec}: {reason}")
    if problems:
        raise InputError("simulate", problems)
    return units


def _counter_faults(simulator: Simulator, units: list[SimulatedUnit], specs: list[str]) -> None:
    """``--counter-fault KEY=FAULT[@SECONDS]``: checked now, made to happen at SECONDS."""
    problems = []
    for spec in specs:
        key, _, rest = spec.partition("=")
        fault, _, after = rest.partition("@")
        having = [u.unit for u in units if key in u.mapping.points(u.options)]
        try:
            seconds = float(after or 30)
            if not having:
                raise ValueRejectedError(f"no simulated unit has {key!r}")
            for unit in having:
                simulator.check_counter_fault(unit, key, fault)
        except ValueError:
            problems.append(f"--counter-fault {spec}: SECONDS must be a number")
        except ValueRejectedError as exc:
            problems.append(f"--counter-fault {spec}: {exc}")
        else:
            simulator.schedule(seconds, [(u, key, fault) for u in having])
    if problems:
        raise InputError("simulate", problems)


def _trip(simulator: Simulator, units: list[tuple[int, Mapping]], faults: list[str]) -> None:
    """``--fault KEY[=LABEL]``: raised in every unit whose mapping has alarm KEY."""
    problems = []
    for fault in faults:
        key, _, label = fault.partition("=")
        having = [unit for unit, mapping in units if key in mapping.entities]
        if not having:
            alarms = sorted({k for _, m in units for k, e in m.entities.items() if e.alarm})
            problems.append(f"--fault {key}: no simulated unit has it (alarms: {alarms})")
        for unit in having:
            try:
                simulator.raise_fault(unit, key, label or None)
            except ValueRejectedError as exc:
                problems.append(f"--fault {fault}: {exc}")
    if problems:
        raise InputError("simulate", problems)


def _option_problems(options: dict[str, str], mappings: list[Mapping]) -> list[str]:
    """An option no mapping has, or a value one of them does not offer, is a mistake."""
    problems = []
    for name, value in options.items():
        specs = [m.options[name] for m in mappings if name in m.options]
        if not specs:
            known = sorted({o for m in mappings for o in m.options})
            problems.append(f"--option {name}: no simulated mapping has it (known: {known})")
        for spec in specs:
            if value not in spec.choices:
                problems.append(f"--option {name}={value}: choose from {list(spec.choices)}")
    return problems


def run_simulate(args: argparse.Namespace, out: TextIO) -> int:
    simulator = build_simulator(args)
    asyncio.run(until_stopped(_serve(simulator, args, out)))
    return 0


async def _serve(simulator: Simulator, args: argparse.Namespace, out: TextIO) -> None:
    served = [f"{m} unit {u}" for m, u in zip(args.mapping, args.unit, strict=True)]
    served += [
        f"sunspec {spec.partition('=')[2]} unit {spec.partition('=')[0]}" for spec in args.sunspec
    ]
    units = ", ".join(served)
    if args.tcp:
        host, _, port = args.tcp.rpartition(":")
        task = asyncio.create_task(
            simulator.serve_tcp(host or "127.0.0.1", int(port), args.framer or "socket")
        )
        await _announce(simulator, task, f"serving {units} on tcp {host}:{port}", out)
        return
    line = {
        "baudrate": args.baudrate,
        "parity": args.parity,
        "stopbits": args.stopbits,
        "framer": args.framer or "rtu",
    }
    if args.serial:
        task = asyncio.create_task(simulator.serve_serial(args.serial, **line))
        await _announce(simulator, task, f"serving {units} on {args.serial}", out)
        return
    with null_modem() as (device_end, bridge_end):
        task = asyncio.create_task(simulator.serve_serial(device_end, **line))
        await _announce(simulator, task, f"serving {units}; open {bridge_end} from the bridge", out)


async def _announce(simulator: Simulator, task: asyncio.Task[None], text: str, out: TextIO) -> None:
    ready = asyncio.create_task(simulator.ready.wait())
    await asyncio.wait({task, ready}, return_when=asyncio.FIRST_COMPLETED)
    if task.done():
        ready.cancel()
        task.result()  # raises the reason it could not serve
        return
    print(text, file=out, flush=True)
    await task
