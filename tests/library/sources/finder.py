"""Finder 7M.38 as mbmd, evcc and modbus_connect read it (facts only).

Input registers (function 4); Finder's document prints 3xxxx numbers with the 30000 memory
reference (30107 is wire 107), the addresses here are wire addresses. Floats are IEEE 754,
high word first.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import (
    EVCC,
    EVCC_3P,
    EVCC_NAN,
    EVCC_PINS_MBMD,
    EVCC_PV,
    MBMD,
    pick,
)

MODBUS_CONNECT = "dmatscheko/modbus_connect@a5a6e49ee80c2d6492619348e041c57f5184a83f"


def _f32(key: str, address: int, unit: str, name: str, scale: float = 1.0) -> SourcePoint:
    return SourcePoint(key, "input", address, "f32", unit, scale, name=name)


def _phases(key: str, address: int, unit: str, name: str) -> tuple[SourcePoint, ...]:
    """Three phase floats in a row from ``address``."""
    return tuple(_f32(f"{key}_l{n}", address + 2 * (n - 1), unit, f"{name}L{n}") for n in (1, 2, 3))


# meters/rs485/finder7m38.go (producer FIND7M38); energies read in Wh and divided by 1000
MBMD_7M38 = (
    *_phases("voltage", 2500, "V", "Voltage"),
    *_phases("current", 2516, "A", "Current"),
    *_phases("power", 2530, "W", "Power"),
    _f32("power", 2536, "W", "Power"),
    *_phases("reactive_power", 2538, "var", "ReactivePower"),
    _f32("reactive_power", 2544, "var", "ReactivePower"),
    *_phases("apparent_power", 2546, "VA", "ApparentPower"),
    _f32("apparent_power", 2552, "VA", "ApparentPower"),
    *_phases("power_factor", 2554, "", "Cosphi"),
    _f32("power_factor", 2560, "", "Cosphi"),
    _f32("phase_angle", 2576, "°", "PhaseAngle"),
    _f32("frequency", 2584, "Hz", "Frequency"),
    *_phases("voltage_thd", 2594, "%", "THD"),
    _f32("energy_import", 2752, "kWh", "Import", 0.001),
    _f32("reactive_energy_import", 2754, "kvarh", "ReactiveImport", 0.001),
    _f32("energy_export", 2756, "kWh", "Export", 0.001),
    _f32("reactive_energy_export", 2758, "kvarh", "ReactiveExport", 0.001),
)


def _u32(key: str, address: int, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, "u32", "Wh", 0.1, name=name)


# custom_components/modbus_connect/device_configs/finder-7m38.yaml
CONNECT_7M38 = (
    _f32("frequency", 2498, "Hz", "Frequency"),
    *(_f32(f"voltage_l{n}", 2498 + 2 * n, "V", f"L{n} Voltage") for n in (1, 2, 3)),
    *(_f32(f"current_l{n}", 2514 + 2 * n, "A", f"L{n} Current") for n in (1, 2, 3)),
    *(_f32(f"power_l{n}", 2528 + 2 * n, "W", f"L{n} active Power") for n in (1, 2, 3)),
    _f32("power", 2536, "W", "Total active Power"),
    *(_f32(f"reactive_power_l{n}", 2536 + 2 * n, "var", f"L{n} reactive Power") for n in (1, 2, 3)),
    _f32("reactive_power", 2544, "var", "Total reactive Power"),
    *(_f32(f"apparent_power_l{n}", 2544 + 2 * n, "VA", f"L{n} apparent Power") for n in (1, 2, 3)),
    _f32("apparent_power", 2552, "VA", "Total apparent Power"),
    *(_f32(f"power_factor_l{n}", 2552 + 2 * n, "", f"L{n} Power Factor") for n in (1, 2, 3)),
    _f32("power_factor", 2560, "", "Total Power Factor"),
    *(_u32(f"counter_n{n}", 460 + 2 * n, f"Counter N{n}") for n in (1, 2, 3, 4)),
)

F7M38 = (
    SourceDefinition(
        device="finder_7m38",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/finder7m38.go",
        points=MBMD_7M38,
        notes=(
            "mbmd reads each value on its own (function 4, two registers), never in blocks",
            "written from Finder's 'Modbus-7M24-7M38_v2_30062021.pdf'; takes energy counters "
            "n1-n4 (2752-2758) as import, reactive import, export, reactive export",
            "reads frequency at 2584 (the document lists Frequency at 32498 and at 32584)",
        ),
    ),
    SourceDefinition(
        device="finder_7m38",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/finder-7m38.yaml",
        points=pick(MBMD_7M38, EVCC_3P),
        notes=(
            "evcc delegates to mbmd (type mbmd, model find7m38); RS-485 only",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="finder_7m38",
        source="community:dmatscheko/modbus_connect",
        ref=f"{MODBUS_CONNECT}:custom_components/modbus_connect/device_configs/finder-7m38.yaml",
        points=CONNECT_7M38,
        notes=(
            "a Home Assistant integration's device file, converted from modbus_local_gateway's "
            "7M_38.yaml; it ships Finder's document (support/devicedocs/finder-7m38)",
            "reads the '1000 x energy counter' integers n1-n4 (30462-30469) unsigned at 0.1 a "
            "count, all four as Wh (the document: n2 and n4 varh, signed 32-bit); keys "
            "counter_n1..4 as it names no direction",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {"finder_7m38": F7M38}
