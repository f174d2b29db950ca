"""Carlo Gavazzi EM24 (RS-485, Ethernet) and EM340 as mbmd, evcc, OpenEMS, Victron, nmakel read them.

Facts only. 32-bit values signed, low word first; mbmd divides by a scaler
(scale = 1/scaler).
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
    OPENEMS,
    OPENEMS_CONVENTION,
    VICTRON,
    VICTRON_STYLE,
    pick,
)


def _s32(key: str, address: int, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, "s32", unit, scale, "little", name)


def _s16(key: str, address: int, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, "s16", unit, scale, name=name)


def _h32(key: str, address: int, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, "s32", unit, scale, "little", name)


def _x(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    order = "little" if type_ == "s32" else "big"
    return SourcePoint(key, "input", address, type_, unit, scale, order, name)


# meters/rs485/carlogavazzi-em24.go (producer CGEM24: the RS-485 EM24)
MBMD_EM24 = (
    _s32("voltage_l1", 0x00, "V", 0.1, "VoltageL1"),
    _s32("voltage_l2", 0x02, "V", 0.1, "VoltageL2"),
    _s32("voltage_l3", 0x04, "V", 0.1, "VoltageL3"),
    _s32("current_l1", 0x0C, "A", 0.001, "CurrentL1"),
    _s32("current_l2", 0x0E, "A", 0.001, "CurrentL2"),
    _s32("current_l3", 0x10, "A", 0.001, "CurrentL3"),
    _s32("power_l1", 0x12, "W", 0.1, "PowerL1"),
    _s32("power_l2", 0x14, "W", 0.1, "PowerL2"),
    _s32("power_l3", 0x16, "W", 0.1, "PowerL3"),
    _s32("power", 0x28, "W", 0.1, "Power"),
    _s16("power_factor_l1", 0x32, "", 0.001, "CosphiL1"),
    _s16("power_factor_l2", 0x33, "", 0.001, "CosphiL2"),
    _s16("power_factor_l3", 0x34, "", 0.001, "CosphiL3"),
    _s16("power_factor", 0x35, "", 0.001, "Cosphi"),
    _s16("frequency", 0x37, "Hz", 0.1, "Frequency"),
    _s32("energy_import", 0x42, "kWh", 0.1, "Import"),
    _s32("energy_import_l1", 0x46, "kWh", 0.1, "ImportL1"),
    _s32("energy_import_l2", 0x48, "kWh", 0.1, "ImportL2"),
    _s32("energy_import_l3", 0x4A, "kWh", 0.1, "ImportL3"),
    _s32("energy_export", 0x5C, "kWh", 0.1, "Export"),
)

# io.openems.edge.meter.carlo.gavazzi/.../em24/MeterCarloGavazziEm24Impl.java and
# common/AbstractMeterCarloGavazziEmSeries.java at 8f573fb6 (function 4)
OPENEMS_EM24 = (
    _s32("voltage_l1", 0x00, "V", 0.1, "VOLTAGE_L1"),
    _s32("voltage_l2", 0x02, "V", 0.1, "VOLTAGE_L2"),
    _s32("voltage_l3", 0x04, "V", 0.1, "VOLTAGE_L3"),
    _s32("current_l1", 0x0C, "A", 0.1, "CURRENT_L1"),
    _s32("current_l2", 0x0E, "A", 0.1, "CURRENT_L2"),
    _s32("current_l3", 0x10, "A", 0.1, "CURRENT_L3"),
    _s32("power_l1", 0x12, "W", 0.1, "ACTIVE_POWER_L1"),
    _s32("power_l2", 0x14, "W", 0.1, "ACTIVE_POWER_L2"),
    _s32("power_l3", 0x16, "W", 0.1, "ACTIVE_POWER_L3"),
    _s32("apparent_power_l1", 0x18, "VA", 0.1, "APPARENT_POWER_L1"),
    _s32("apparent_power_l2", 0x1A, "VA", 0.1, "APPARENT_POWER_L2"),
    _s32("apparent_power_l3", 0x1C, "VA", 0.1, "APPARENT_POWER_L3"),
    _s32("reactive_power_l1", 0x1E, "var", 0.1, "REACTIVE_POWER_L1"),
    _s32("reactive_power_l2", 0x20, "var", 0.1, "REACTIVE_POWER_L2"),
    _s32("reactive_power_l3", 0x22, "var", 0.1, "REACTIVE_POWER_L3"),
    _s32("power", 0x28, "W", 0.1, "ACTIVE_POWER"),
    _s32("apparent_power", 0x2A, "VA", 0.1, "APPARENT_POWER"),
    _s32("reactive_power", 0x2C, "var", 0.1, "REACTIVE_POWER"),
    SourcePoint("frequency", "input", 0x37, "u16", "Hz", 0.1, name="FREQUENCY"),
    _s32("energy_import", 0x3E, "kWh", 0.1, "ACTIVE_PRODUCTION_ENERGY"),
    _s32("energy_export", 0x5C, "kWh", 0.1, "ACTIVE_CONSUMPTION_ENERGY"),
)

# meters/rs485/carlogavazzi-ex3x0.go (producer CGEX3X0: EM330, EM340, ET330, ET340)
MBMD_EX3X0 = (
    _s32("voltage_l1", 0x00, "V", 0.1, "VoltageL1"),
    _s32("voltage_l2", 0x02, "V", 0.1, "VoltageL2"),
    _s32("voltage_l3", 0x04, "V", 0.1, "VoltageL3"),
    _s32("current_l1", 0x0C, "A", 0.001, "CurrentL1"),
    _s32("current_l2", 0x0E, "A", 0.001, "CurrentL2"),
    _s32("current_l3", 0x10, "A", 0.001, "CurrentL3"),
    _s32("power_l1", 0x12, "W", 0.1, "PowerL1"),
    _s32("power_l2", 0x14, "W", 0.1, "PowerL2"),
    _s32("power_l3", 0x16, "W", 0.1, "PowerL3"),
    _s32("power", 0x28, "W", 0.1, "Power"),
    _s16("power_factor_l1", 0x2E, "", 0.001, "CosphiL1"),
    _s16("power_factor_l2", 0x2F, "", 0.001, "CosphiL2"),
    _s16("power_factor_l3", 0x30, "", 0.001, "CosphiL3"),
    _s16("power_factor", 0x31, "", 0.001, "Cosphi"),
    _s16("frequency", 0x33, "Hz", 0.1, "Frequency"),
    _s32("energy_import", 0x34, "kWh", 0.1, "Import"),
    _s32("energy_import_l1", 0x40, "kWh", 0.1, "ImportL1"),
    _s32("energy_import_l2", 0x42, "kWh", 0.1, "ImportL2"),
    _s32("energy_import_l3", 0x44, "kWh", 0.1, "ImportL3"),
    _s32("energy_export", 0x4E, "kWh", 0.1, "Export"),
)

# io.openems.edge.meter.carlo.gavazzi/.../em300/MeterCarloGavazziEm300Impl.java (function 4)
OPENEMS_EM300 = (
    _s32("voltage_l1", 0x00, "V", 0.1, "VOLTAGE_L1"),
    _s32("voltage_l2", 0x02, "V", 0.1, "VOLTAGE_L2"),
    _s32("voltage_l3", 0x04, "V", 0.1, "VOLTAGE_L3"),
    _s32("current_l1", 0x0C, "A", 0.001, "CURRENT_L1"),
    _s32("current_l2", 0x0E, "A", 0.001, "CURRENT_L2"),
    _s32("current_l3", 0x10, "A", 0.001, "CURRENT_L3"),
    _s32("power_l1", 0x12, "W", 0.1, "ACTIVE_POWER_L1"),
    _s32("power_l2", 0x14, "W", 0.1, "ACTIVE_POWER_L2"),
    _s32("power_l3", 0x16, "W", 0.1, "ACTIVE_POWER_L3"),
    _s32("apparent_power_l1", 0x18, "VA", 0.1, "APPARENT_POWER_L1"),
    _s32("apparent_power_l2", 0x1A, "VA", 0.1, "APPARENT_POWER_L2"),
    _s32("apparent_power_l3", 0x1C, "VA", 0.1, "APPARENT_POWER_L3"),
    _s32("reactive_power_l1", 0x1E, "var", 0.1, "REACTIVE_POWER_L1"),
    _s32("reactive_power_l2", 0x20, "var", 0.1, "REACTIVE_POWER_L2"),
    _s32("reactive_power_l3", 0x22, "var", 0.1, "REACTIVE_POWER_L3"),
    _s32("power", 0x28, "W", 0.1, "ACTIVE_POWER"),
    _s32("apparent_power", 0x2A, "VA", 0.1, "APPARENT_POWER"),
    _s32("reactive_power", 0x2C, "var", 0.1, "REACTIVE_POWER"),
    SourcePoint("frequency", "input", 0x33, "u16", "Hz", 0.1, name="FREQUENCY"),
    _s32("energy_import", 0x34, "kWh", 0.1, "ACTIVE_PRODUCTION_ENERGY"),
    _s32("energy_export", 0x4E, "kWh", 0.1, "ACTIVE_CONSUMPTION_ENERGY"),
)

# meters/rs485/carlogavazzi-em24_e1.go (producer CGEM24_E1: the Ethernet EM24)
MBMD_EM24_E1 = (
    _s32("voltage_l1", 0x00, "V", 0.1, "VoltageL1"),
    _s32("voltage_l2", 0x02, "V", 0.1, "VoltageL2"),
    _s32("voltage_l3", 0x04, "V", 0.1, "VoltageL3"),
    _s32("current_l1", 0x0C, "A", 0.001, "CurrentL1"),
    _s32("current_l2", 0x0E, "A", 0.001, "CurrentL2"),
    _s32("current_l3", 0x10, "A", 0.001, "CurrentL3"),
    _s32("power_l1", 0x12, "W", 0.1, "PowerL1"),
    _s32("power_l2", 0x14, "W", 0.1, "PowerL2"),
    _s32("power_l3", 0x16, "W", 0.1, "PowerL3"),
    _s32("power", 0x28, "W", 0.1, "Power"),
    _s16("power_factor_l1", 0x2E, "", 0.001, "CosphiL1"),
    _s16("power_factor_l2", 0x2F, "", 0.001, "CosphiL2"),
    _s16("power_factor_l3", 0x30, "", 0.001, "CosphiL3"),
    _s16("power_factor", 0x31, "", 0.001, "Cosphi"),
    _s16("frequency", 0x33, "Hz", 0.1, "Frequency"),
    _s32("energy_import", 0x34, "kWh", 0.1, "Import"),
    _s32("energy_import_l1", 0x40, "kWh", 0.1, "ImportL1"),
    _s32("energy_import_l2", 0x42, "kWh", 0.1, "ImportL2"),
    _s32("energy_import_l3", 0x44, "kWh", 0.1, "ImportL3"),
    _s32("energy_export", 0x4E, "kWh", 0.1, "Export"),
)

# carlo_gavazzi.py (class EM24_Meter, EM24 Ethernet), three-phase configuration
VICTRON_EM24_E1 = (
    _h32("voltage_l1", 0x00, "V", 0.1, "/Ac/L1/Voltage"),
    _h32("voltage_l2", 0x02, "V", 0.1, "/Ac/L2/Voltage"),
    _h32("voltage_l3", 0x04, "V", 0.1, "/Ac/L3/Voltage"),
    _h32("current_l1", 0x0C, "A", 0.001, "/Ac/L1/Current"),
    _h32("current_l2", 0x0E, "A", 0.001, "/Ac/L2/Current"),
    _h32("current_l3", 0x10, "A", 0.001, "/Ac/L3/Current"),
    _h32("power_l1", 0x12, "W", 0.1, "/Ac/L1/Power"),
    _h32("power_l2", 0x14, "W", 0.1, "/Ac/L2/Power"),
    _h32("power_l3", 0x16, "W", 0.1, "/Ac/L3/Power"),
    _h32("power", 0x28, "W", 0.1, "/Ac/Power"),
    SourcePoint("frequency", "holding", 0x33, "u16", "Hz", 0.1, name="/Ac/Frequency"),
    _h32("energy_import", 0x34, "kWh", 0.1, "/Ac/Energy/Forward"),
    _h32("energy_import_l1", 0x40, "kWh", 0.1, "/Ac/L1/Energy/Forward"),
    _h32("energy_import_l2", 0x42, "kWh", 0.1, "/Ac/L2/Energy/Forward"),
    _h32("energy_import_l3", 0x44, "kWh", 0.1, "/Ac/L3/Energy/Forward"),
    _h32("energy_export", 0x4E, "kWh", 0.1, "/Ac/Energy/Reverse"),
)

# nmakel/sdm_modbus src/sdm_modbus/carlogavazzi.py (class EM24, from the EM24 Ethernet
# protocol), input registers, words low first
NMAKEL_EM24_E1 = (
    _x("voltage_l1", 0x00, "s32", "V", 0.1, "l1_voltage"),
    _x("voltage_l2", 0x02, "s32", "V", 0.1, "l2_voltage"),
    _x("voltage_l3", 0x04, "s32", "V", 0.1, "l3_voltage"),
    _x("voltage_l1_l2", 0x06, "s32", "V", 0.1, "l12_voltage"),
    _x("voltage_l2_l3", 0x08, "s32", "V", 0.1, "l23_voltage"),
    _x("voltage_l3_l1", 0x0A, "s32", "V", 0.1, "l31_voltage"),
    _x("current_l1", 0x0C, "s32", "A", 0.001, "l1_current"),
    _x("current_l2", 0x0E, "s32", "A", 0.001, "l2_current"),
    _x("current_l3", 0x10, "s32", "A", 0.001, "l3_current"),
    _x("power_l1", 0x12, "s32", "W", 0.1, "l1_power_active"),
    _x("power_l2", 0x14, "s32", "W", 0.1, "l2_power_active"),
    _x("power_l3", 0x16, "s32", "W", 0.1, "l3_power_active"),
    _x("apparent_power_l1", 0x18, "s32", "VA", 0.1, "l1_power_apparent"),
    _x("apparent_power_l2", 0x1A, "s32", "VA", 0.1, "l2_power_apparent"),
    _x("apparent_power_l3", 0x1C, "s32", "VA", 0.1, "l3_power_apparent"),
    _x("reactive_power_l1", 0x1E, "s32", "var", 0.1, "l1_power_reactive"),
    _x("reactive_power_l2", 0x20, "s32", "var", 0.1, "l2_power_reactive"),
    _x("reactive_power_l3", 0x22, "s32", "var", 0.1, "l3_power_reactive"),
    _x("voltage_average", 0x24, "s32", "V", 0.1, "voltage_ln"),
    _x("voltage_line_average", 0x26, "s32", "V", 0.1, "voltage_ll"),
    _x("power", 0x28, "s32", "W", 0.1, "power_active"),
    _x("apparent_power", 0x2A, "s32", "VA", 0.1, "power_apparent"),
    _x("reactive_power", 0x2C, "s32", "var", 0.1, "power_reactive"),
    _x("power_factor_l1", 0x2E, "s16", "", 0.001, "l1_power_factor"),
    _x("power_factor_l2", 0x2F, "s16", "", 0.001, "l2_power_factor"),
    _x("power_factor_l3", 0x30, "s16", "", 0.001, "l3_power_factor"),
    _x("power_factor", 0x31, "s16", "", 0.001, "total_pf"),
    _x("frequency", 0x33, "u16", "Hz", 0.1, "frequency"),
    _x("energy_import", 0x34, "s32", "kWh", 0.1, "import_energy_active"),
    _x("reactive_energy_import", 0x36, "s32", "kvarh", 0.1, "import_energy_reactive"),
    _x("demand_power", 0x38, "s32", "W", 0.1, "demand_power_active"),
    _x("max_demand_power", 0x3A, "s32", "W", 0.1, "maximum_demand_power_active"),
    _x("energy_import_l1", 0x40, "s32", "kWh", 0.1, "l1_import_energy_active"),
    _x("energy_import_l2", 0x42, "s32", "kWh", 0.1, "l2_import_energy_active"),
    _x("energy_import_l3", 0x44, "s32", "kWh", 0.1, "l3_import_energy_active"),
    _x("energy_export", 0x4E, "s32", "kWh", 0.1, "export_energy_active"),
    _x("reactive_energy_export", 0x50, "s32", "kvarh", 0.1, "export_energy_reactive"),
    _x("demand_apparent_power", 0x76, "s32", "VA", 0.1, "demand_power_apparent"),
    _x("max_demand_apparent_power", 0x78, "s32", "VA", 0.1, "maximum_demand_power_apparent"),
)

_MBMD_NOTE = "mbmd reads each value on its own (function 4), never in blocks"
_EVCC_EM24 = tuple(k for k in EVCC_3P if k != "energy_export")

EM24 = (
    SourceDefinition(
        device="carlo_gavazzi_em24",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/carlogavazzi-em24.go",
        points=MBMD_EM24,
        notes=(
            _MBMD_NOTE,
            "energy counters are read as signed 32-bit (low word first)",
            "the Ethernet EM24 (EM24_E1) has another map from 0x2e on: see the device "
            "carlo_gavazzi_em24_e1",
        ),
    ),
    SourceDefinition(
        device="carlo_gavazzi_em24",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/cg-em24.yaml",
        points=pick(MBMD_EM24, _EVCC_EM24),
        notes=(
            "evcc delegates to mbmd (type mbmd, model cgem24); EM24 with RS-485 only, "
            "evcc has a separate cg-em24_e1 template (model cgem24_e1) for the Ethernet EM24",
            "evcc no longer reads export energy 0x5c (evcc-io/evcc PR 31736, issue 31143): "
            "some EM24 variants/configurations answer exception 2 for it",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="carlo_gavazzi_em24",
        source="openems",
        ref="OpenEMS/openems@8f573fb6acd26ebff56915004366525551486e53:"
        "io.openems.edge.meter.carlo.gavazzi/src/io/openems/edge/meter/carlo/gavazzi/em24/"
        "MeterCarloGavazziEm24Impl.java",
        points=OPENEMS_EM24,
        notes=(
            OPENEMS_CONVENTION,
            "an EM24 component of a stored OpenEMS version (with common/"
            "AbstractMeterCarloGavazziEmSeries.java at the same commit); the current "
            "snapshot has only EM100 and EM300 components",
            "it scales the currents by 100 into mA (0.1 A per count) where mbmd and its own "
            "EM300 take mA (0.001 A per count)",
            "it reads kWh(+) TOT at 0x3e where mbmd reads import at 0x42",
            "reads in small blocks: 0x00-0x05, 0x0c-0x11, 0x12-0x17, 0x18-0x1d, 0x1e-0x23, "
            "0x28-0x2d, then 0x37, 0x3e, 0x5c one at a time",
        ),
    ),
)

EM24_E1 = (
    SourceDefinition(
        device="carlo_gavazzi_em24_e1",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/carlogavazzi-em24_e1.go",
        points=MBMD_EM24_E1,
        notes=(_MBMD_NOTE, "energy counters are read as signed 32-bit (low word first)"),
    ),
    SourceDefinition(
        device="carlo_gavazzi_em24_e1",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/cg-em24_e1.yaml",
        points=pick(MBMD_EM24_E1, EVCC_3P),
        notes=(
            "evcc delegates to mbmd (type mbmd, model cgem24_e1); unlike its RS-485 EM24 "
            "template it still reads export energy",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="carlo_gavazzi_em24_e1",
        source="victron",
        ref=f"{VICTRON}:carlo_gavazzi.py",
        points=VICTRON_EM24_E1,
        notes=(
            VICTRON_STYLE,
            "identifies the model by holding 0x000b (u16): 1648..1653 are the EM24DINAV23XE1 "
            "and EM24DINAV53XE1 X/PFA/PFB variants",
            "WRITES holding 0xa000 (application) to 7 ('H') at start when it reads otherwise: "
            "the export counters depend on the application setting",
            "reads the phase configuration at holding 0x1002 (0 3P.n, 1 3P.1, 2 2P, 3 1P, "
            "4 3P) and only the phases it has; phase sequence 0x32 (0 or 0xffff) on 3 phases; "
            "front selector position 0xa100 (0 kVARh, 1 '2', 2 '1', 3 Locked)",
            "frequency is read unsigned 16-bit (mbmd: signed)",
        ),
    ),
    SourceDefinition(
        device="carlo_gavazzi_em24_e1",
        source="community:nmakel/sdm_modbus",
        ref="nmakel/sdm_modbus@fead352846b36ff8ca9f89c1491ee047ab2b55d1:"
        "src/sdm_modbus/carlogavazzi.py",
        points=NMAKEL_EM24_E1,
        notes=(
            "class EM24 of a Python library for meters, written from the EM24 Ethernet "
            "protocol; also lists the phase sequence at 0x32 (s16), no library key",
        ),
    ),
)

EM340 = (
    SourceDefinition(
        device="carlo_gavazzi_em340",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/carlogavazzi-ex3x0.go",
        points=MBMD_EX3X0,
        notes=(
            _MBMD_NOTE,
            "one producer for EM330, EM340, ET330 and ET340",
            "energy counters are read as signed 32-bit (low word first)",
        ),
    ),
    SourceDefinition(
        device="carlo_gavazzi_em340",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/cg-emt3xx.yaml",
        points=pick(MBMD_EX3X0, EVCC_3P),
        notes=(
            "evcc delegates to mbmd (type mbmd, model cgex3x0); the template lists "
            "ET330/ET340, EM330/EM340, EM530/EM540 over RS-485 or TCP",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="carlo_gavazzi_em340",
        source="openems",
        ref=f"{OPENEMS}:io.openems.edge.meter.carlo.gavazzi/src/io/openems/edge/meter/"
        "carlo/gavazzi/em300/MeterCarloGavazziEm300Impl.java",
        points=OPENEMS_EM300,
        notes=(
            OPENEMS_CONVENTION,
            "one component for the EM300 series (EM330, EM340); reads in three blocks: "
            "0x00-0x05, 0x0c-0x2d, 0x33-0x4f",
            "frequency is read unsigned 16-bit (mbmd: signed); energy counters signed 32-bit "
            "low word first",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "carlo_gavazzi_em24": EM24,
    "carlo_gavazzi_em24_e1": EM24_E1,
    "carlo_gavazzi_em340": EM340,
}
