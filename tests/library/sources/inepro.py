"""Inepro PRO380-Mod as mbmd, evcc and nymea read it (facts only).

Every value is an IEEE 754 float32, high word first, in holding registers (function 3);
powers in kW, kvar and kVA, energies in kWh and kvarh.
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

NYMEA = "nymea/nymea-plugins-modbus@fcffebb46865b603bbdfd840529eec07e33de45b"


def _f32(key: str, address: int, unit: str, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, "f32", unit, name=name)


def _phases(key: str, address: int, unit: str, name: str) -> tuple[SourcePoint, ...]:
    """The total at ``address`` and its three phases in the next three floats."""
    phases = (_f32(f"{key}_l{n}", address + 2 * n, unit, f"{name}L{n}") for n in (1, 2, 3))
    return (_f32(key, address, unit, name), *phases)


def _tariffs(key: str, address: int, unit: str, name: str) -> tuple[SourcePoint, ...]:
    """A counter, its tariffs T1 and T2, and its three phases: six floats in a row."""
    phases = (_f32(f"{key}_l{n}", address + 4 + 2 * n, unit, f"{name}L{n}") for n in (1, 2, 3))
    return (
        _f32(key, address, unit, name),
        _f32(f"{key}_t1", address + 2, unit, f"{name}T1"),
        _f32(f"{key}_t2", address + 4, unit, f"{name}T2"),
        *phases,
    )


# meters/rs485/inepro.go (producer INEPRO; powers read in kW, scaled to W by mbmd)
MBMD_PRO380 = (
    _f32("voltage", 0x5000, "V", "Voltage"),
    _f32("voltage_l1", 0x5002, "V", "VoltageL1"),
    _f32("voltage_l2", 0x5004, "V", "VoltageL2"),
    _f32("voltage_l3", 0x5006, "V", "VoltageL3"),
    _f32("frequency", 0x5008, "Hz", "Frequency"),
    *_phases("current", 0x500A, "A", "Current"),
    *_phases("power", 0x5012, "kW", "Power"),
    *_phases("reactive_power", 0x501A, "kvar", "ReactivePower"),
    *_phases("apparent_power", 0x5022, "kVA", "ApparentPower"),
    *_phases("power_factor", 0x502A, "", "Cosphi"),
    *_tariffs("energy_total", 0x6000, "kWh", "Sum"),
    *_tariffs("energy_import", 0x600C, "kWh", "Import"),
    *_tariffs("energy_export", 0x6018, "kWh", "Export"),
    *_tariffs("reactive_energy_total", 0x6024, "kvarh", "ReactiveSum"),
    *_tariffs("reactive_energy_import", 0x6030, "kvarh", "ReactiveImport"),
    *_tariffs("reactive_energy_export", 0x603C, "kvarh", "ReactiveExport"),
)

# inepro/pro380-registers.json (class Pro380: RTU, big endian, holding registers)
NYMEA_PRO380 = (
    _f32("voltage_l1", 0x5002, "V", "voltagePhaseA"),
    _f32("voltage_l2", 0x5004, "V", "voltagePhaseB"),
    _f32("voltage_l3", 0x5006, "V", "voltagePhaseC"),
    _f32("frequency", 0x5008, "Hz", "frequency"),
    _f32("current_l1", 0x500C, "A", "currentPhaseA"),
    _f32("current_l2", 0x500E, "A", "currentPhaseB"),
    _f32("current_l3", 0x5010, "A", "currentPhaseC"),
    _f32("power", 0x5012, "kW", "totalCurrentPower"),
    _f32("power_l1", 0x5014, "kW", "powerPhaseA"),
    _f32("power_l2", 0x5016, "kW", "powerPhaseB"),
    _f32("power_l3", 0x5018, "kW", "powerPhaseC"),
    _f32("energy_import", 0x600C, "kWh", "totalEnergyConsumed"),
    _f32("energy_import_l1", 0x6012, "kWh", "energyConsumedPhaseA"),
    _f32("energy_import_l2", 0x6014, "kWh", "energyConsumedPhaseB"),
    _f32("energy_import_l3", 0x6016, "kWh", "energyConsumedPhaseC"),
    _f32("energy_export", 0x6018, "kWh", "totalEnergyProduced"),
    _f32("energy_export_l1", 0x601E, "kWh", "energyProducedPhaseA"),
    _f32("energy_export_l2", 0x6020, "kWh", "energyProducedPhaseB"),
    _f32("energy_export_l3", 0x6022, "kWh", "energyProducedPhaseC"),
)

PRO380 = (
    SourceDefinition(
        device="inepro_pro380",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/inepro.go",
        points=MBMD_PRO380,
        notes=(
            "mbmd reads each value on its own (function 3, two registers), never in blocks",
            "written from the PRO380 user manual V2.18; the keys 'voltage' and 'current' are "
            "its Voltage (0x5000) and Current (0x500a)",
        ),
    ),
    SourceDefinition(
        device="inepro_pro380",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/inepro.yaml",
        points=pick(MBMD_PRO380, EVCC_3P),
        notes=(
            "evcc delegates to mbmd (type mbmd, model inepro); product PRO380-MOD, RS-485 only",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="inepro_pro380",
        source="community:nymea/nymea-plugins-modbus",
        ref=f"{NYMEA}:inepro/pro380-registers.json",
        points=NYMEA_PRO380,
        notes=(
            "nymea's PRO380 plugin (Modbus RTU): reads in blocks of the three phases "
            "(0x5002-0x5007, 0x500c-0x5011, 0x6012-0x6017, 0x601e-0x6023) and of the four "
            "powers (0x5012-0x5019); multiplies the kW by 1000 into W",
            "checks the meter answers by the forward active energy (0x600c)",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {"inepro_pro380": PRO380}
