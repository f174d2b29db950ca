"""Saia-Burgess Controls (SBC) ALE3 as mbmd, evcc and SBC's data sheet read it (facts only).

Holding registers (function 3); the data sheet numbers registers from 1, mbmd subtracts
one: the addresses here are wire addresses. 32-bit counters high word first.
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

DATASHEET = (
    "Saia-Burgess Controls, Energy meter ALE3 with integrated Serial Modbus interface, "
    "Datasheet (26-527 ENG), page 6 'Registers' (rows 1-37 read)"
)


def _h(key: str, register: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    """A point at the data sheet's 1-based register number."""
    return SourcePoint(key, "holding", register - 1, type_, unit, scale, name=name)


def _phase(n: int) -> tuple[SourcePoint, ...]:
    """mbmd's five registers of phase n (1-3): U, I, P, Q, cos phi."""
    base = 36 + 5 * (n - 1)
    return (
        _h(f"voltage_l{n}", base, "u16", "V", 1.0, f"VoltageL{n}"),
        _h(f"current_l{n}", base + 1, "u16", "A", 0.1, f"CurrentL{n}"),
        _h(f"power_l{n}", base + 2, "u16", "W", 0.01, f"PowerL{n}"),
        _h(f"reactive_power_l{n}", base + 3, "u16", "var", 0.01, f"ReactivePowerL{n}"),
        _h(f"power_factor_l{n}", base + 4, "u16", "", 0.01, f"CosphiL{n}"),
    )


# meters/rs485/sbc.go (producer SBC, "Saia Burgess Controls ALE3 meters")
MBMD_ALE3 = (
    _h("energy_import", 28, "u32", "kWh", 0.01, "Import"),
    _h("energy_export", 32, "u32", "kWh", 0.01, "Export"),
    *_phase(1),
    *_phase(2),
    *_phase(3),
    _h("power", 51, "u16", "W", 0.01, "Power"),
    _h("reactive_power", 52, "u16", "var", 0.01, "ReactivePower"),
)

# the rows of the data sheet's register table that were readable
VENDOR_ALE3 = (
    _h("energy_t1", 28, "u32", "kWh", 0.01, "WT1 total"),
    _h("resettable_energy_t1", 30, "u32", "kWh", 0.01, "WT1 partial"),
    _h("energy_t2", 32, "u32", "kWh", 0.01, "WT2 total"),
    _h("resettable_energy_t2", 34, "u32", "kWh", 0.01, "WT2 partial"),
    _h("voltage_l1", 36, "u16", "V", 1.0, "URMS phase 1"),
    _h("current_l1", 37, "u16", "A", 0.1, "IRMS phase 1"),
)

ALE3 = (
    SourceDefinition(
        device="saia_ale3",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/sbc.go",
        points=MBMD_ALE3,
        notes=(
            "mbmd reads each value on its own (function 3), never in blocks",
            "it divides the powers (0.01 kW, 0.01 kvar a count) by 100 and reports the kW "
            "number as W; reads powers and cos phi unsigned (mbmd PR 394, after this "
            "snapshot, scales them to W and reads reactive power signed: mbmd issue 393)",
            "reads the tariff 1 and tariff 2 totals (registers 28, 32) as import and export",
        ),
    ),
    SourceDefinition(
        device="saia_ale3",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/sbc-axx3.yaml",
        points=pick(MBMD_ALE3, EVCC_3P),
        notes=(
            "evcc delegates to mbmd (type mbmd, model sbc); the template names the ALE3 and "
            "the AWD3, RS-485 only",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="saia_ale3",
        source="vendor",
        ref=DATASHEET,
        points=VENDOR_ALE3,
        notes=(
            "double registers high word first; the partial counters reset by writing 0 to "
            "both registers in one message",
            "rows 7-14 read the type as text ('AL', 'E3', 'D5', 'FD', '10', 'C2'/'C3' non-MID/"
            "MID, 'A0'); row 25 is the phase error register, row 27 the tariff (0 T1, 4 T2)",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {"saia_ale3": ALE3}
