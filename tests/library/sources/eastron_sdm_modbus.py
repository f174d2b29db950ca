"""Eastron SDM meters as nmakel/sdm_modbus (a Python library for them) reads them (facts only).

Its register tables list every value of the SDM72D-M V2, SDM120, SDM230 and SDM630 in
input registers as float32, high word first, at scale 1. Only input registers with a
library key are listed; holding (settings) registers are left out.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint

REF = "nmakel/sdm_modbus@fead352846b36ff8ca9f89c1491ee047ab2b55d1:src/sdm_modbus/sdm.py"
SOURCE = "community:nmakel/sdm_modbus"
STYLE = (
    "read_all() reads each batch of input registers in one request (its own batch numbers "
    "group the table); one value at a time with read()"
)


def _f32(key: str, address: int, unit: str, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, "f32", unit, name=name)


# class SDM630
SDM630 = (
    _f32("voltage_l1", 0x0000, "V", "l1_voltage"),
    _f32("voltage_l2", 0x0002, "V", "l2_voltage"),
    _f32("voltage_l3", 0x0004, "V", "l3_voltage"),
    _f32("current_l1", 0x0006, "A", "l1_current"),
    _f32("current_l2", 0x0008, "A", "l2_current"),
    _f32("current_l3", 0x000A, "A", "l3_current"),
    _f32("power_l1", 0x000C, "W", "l1_power_active"),
    _f32("power_l2", 0x000E, "W", "l2_power_active"),
    _f32("power_l3", 0x0010, "W", "l3_power_active"),
    _f32("apparent_power_l1", 0x0012, "VA", "l1_power_apparent"),
    _f32("apparent_power_l2", 0x0014, "VA", "l2_power_apparent"),
    _f32("apparent_power_l3", 0x0016, "VA", "l3_power_apparent"),
    _f32("reactive_power_l1", 0x0018, "var", "l1_power_reactive"),
    _f32("reactive_power_l2", 0x001A, "var", "l2_power_reactive"),
    _f32("reactive_power_l3", 0x001C, "var", "l3_power_reactive"),
    _f32("power_factor_l1", 0x001E, "", "l1_power_factor"),
    _f32("power_factor_l2", 0x0020, "", "l2_power_factor"),
    _f32("power_factor_l3", 0x0022, "", "l3_power_factor"),
    _f32("phase_angle_l1", 0x0024, "°", "l1_phase_angle"),
    _f32("phase_angle_l2", 0x0026, "°", "l2_phase_angle"),
    _f32("phase_angle_l3", 0x0028, "°", "l3_phase_angle"),
    _f32("voltage_average", 0x002A, "V", "voltage_ln"),
    _f32("current_average", 0x002E, "A", "current_ln"),
    _f32("current_sum", 0x0030, "A", "total_line_current"),
    _f32("power", 0x0034, "W", "total_power_active"),
    _f32("apparent_power", 0x0038, "VA", "total_power_apparent"),
    _f32("reactive_power", 0x003C, "var", "total_power_reactive"),
    _f32("power_factor", 0x003E, "", "total_power_factor"),
    _f32("phase_angle", 0x0042, "°", "total_phase_angle"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "import_energy_active"),
    _f32("energy_export", 0x004A, "kWh", "export_energy_active"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "import_energy_reactive"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "export_energy_reactive"),
    _f32("apparent_energy", 0x0050, "kVAh", "total_energy_apparent"),
    _f32("demand_power", 0x0054, "W", "total_import_demand_power_active"),
    _f32("max_demand_power", 0x0056, "VA", "maximum_import_demand_power_apparent"),
    _f32("import_demand_power", 0x0058, "W", "import_demand_power_active"),
    _f32("max_import_demand_power", 0x005A, "W", "maximum_import_demand_power_active"),
    _f32("export_demand_power", 0x005C, "W", "export_demand_power_active"),
    _f32("max_export_demand_power", 0x005E, "W", "maximum_export_demand_power_active"),
    _f32("demand_apparent_power", 0x0064, "VA", "total_demand_power_apparent"),
    _f32("max_demand_apparent_power", 0x0066, "VA", "maximum_demand_power_apparent"),
    _f32("current_demand_n", 0x0068, "A", "neutral_demand_current"),
    _f32("max_current_demand_n", 0x006A, "A", "maximum_neutral_demand_current"),
    _f32("voltage_l1_l2", 0x00C8, "V", "l12_voltage"),
    _f32("voltage_l2_l3", 0x00CA, "V", "l23_voltage"),
    _f32("voltage_l3_l1", 0x00CC, "V", "l31_voltage"),
    _f32("voltage_line_average", 0x00CE, "V", "voltage_ll"),
    _f32("current_n", 0x00E0, "A", "neutral_current"),
    _f32("voltage_thd_l1", 0x00EA, "%", "l1n_voltage_thd"),
    _f32("voltage_thd_l2", 0x00EC, "%", "l2n_voltage_thd"),
    _f32("voltage_thd_l3", 0x00EE, "%", "l3n_voltage_thd"),
    _f32("current_thd_l1", 0x00F0, "%", "l1_current_thd"),
    _f32("current_thd_l2", 0x00F2, "%", "l2_current_thd"),
    _f32("current_thd_l3", 0x00F4, "%", "l3_current_thd"),
    _f32("voltage_thd", 0x00F8, "%", "voltage_ln_thd"),
    _f32("current_thd", 0x00FA, "%", "current_thd"),
    _f32("current_demand_l1", 0x0102, "A", "l1_demand_current"),
    _f32("current_demand_l2", 0x0104, "A", "l2_demand_current"),
    _f32("current_demand_l3", 0x0106, "A", "l3_demand_current"),
    _f32("max_current_demand_l1", 0x0108, "A", "maximum_l1_demand_current"),
    _f32("max_current_demand_l2", 0x010A, "A", "maximum_l2_demand_current"),
    _f32("max_current_demand_l3", 0x010C, "A", "maximum_l3_demand_current"),
    _f32("voltage_thd_l1_l2", 0x014E, "%", "l12_voltage_thd"),
    _f32("voltage_thd_l2_l3", 0x0150, "%", "l23_voltage_thd"),
    _f32("voltage_thd_l3_l1", 0x0152, "%", "l31_voltage_thd"),
    _f32("voltage_line_thd", 0x0154, "%", "voltage_ll_thd"),
    _f32("energy_total", 0x0156, "kWh", "total_energy_active"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "total_energy_reactive"),
    _f32("energy_import_l1", 0x015A, "kWh", "l1_import_energy_active"),
    _f32("energy_import_l2", 0x015C, "kWh", "l2_import_energy_active"),
    _f32("energy_import_l3", 0x015E, "kWh", "l3_import_energy_active"),
    _f32("energy_export_l1", 0x0160, "kWh", "l1_export_energy_active"),
    _f32("energy_export_l2", 0x0162, "kWh", "l2_export_energy_active"),
    _f32("energy_export_l3", 0x0164, "kWh", "l3_export_energy_active"),
    _f32("energy_total_l1", 0x0166, "kWh", "l1_energy_active"),
    _f32("energy_total_l2", 0x0168, "kWh", "l2_energy_active"),
    _f32("energy_total_l3", 0x016A, "kWh", "l3_energy_active"),
    _f32("reactive_energy_import_l1", 0x016C, "kvarh", "l1_import_energy_reactive"),
    _f32("reactive_energy_import_l2", 0x016E, "kvarh", "l2_import_energy_reactive"),
    _f32("reactive_energy_import_l3", 0x0170, "kvarh", "l3_import_energy_reactive"),
    _f32("reactive_energy_export_l1", 0x0172, "kvarh", "l1_export_energy_reactive"),
    _f32("reactive_energy_export_l2", 0x0174, "kvarh", "l2_export_energy_reactive"),
    _f32("reactive_energy_export_l3", 0x0176, "kvarh", "l3_export_energy_reactive"),
    _f32("reactive_energy_total_l1", 0x0178, "kvarh", "l1_energy_reactive"),
    _f32("reactive_energy_total_l2", 0x017A, "kvarh", "l2_energy_reactive"),
    _f32("reactive_energy_total_l3", 0x017C, "kvarh", "l3_energy_reactive"),
)

# class SDM120
SDM120 = (
    _f32("voltage", 0x0000, "V", "voltage"),
    _f32("current", 0x0006, "A", "current"),
    _f32("power", 0x000C, "W", "power_active"),
    _f32("apparent_power", 0x0012, "VA", "power_apparent"),
    _f32("reactive_power", 0x0018, "var", "power_reactive"),
    _f32("power_factor", 0x001E, "", "power_factor"),
    _f32("phase_angle", 0x0024, "°", "phase_angle"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "import_energy_active"),
    _f32("energy_export", 0x004A, "kWh", "export_energy_active"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "import_energy_reactive"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "export_energy_reactive"),
    _f32("demand_power", 0x0054, "W", "total_demand_power_active"),
    _f32("max_demand_power", 0x0056, "W", "maximum_total_demand_power_active"),
    _f32("import_demand_power", 0x0058, "W", "import_demand_power_active"),
    _f32("max_import_demand_power", 0x005A, "W", "maximum_import_demand_power_active"),
    _f32("export_demand_power", 0x005C, "W", "export_demand_power_active"),
    _f32("max_export_demand_power", 0x005E, "W", "maximum_export_demand_power_active"),
    _f32("current_demand", 0x0102, "A", "total_demand_current"),
    _f32("max_current_demand", 0x0108, "A", "maximum_total_demand_current"),
    _f32("energy_total", 0x0156, "kWh", "total_energy_active"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "total_energy_reactive"),
)

# class SDM230
SDM230 = (
    _f32("voltage", 0x0000, "V", "voltage"),
    _f32("current", 0x0006, "A", "current"),
    _f32("power", 0x000C, "W", "power_active"),
    _f32("apparent_power", 0x0012, "VA", "power_apparent"),
    _f32("reactive_power", 0x0018, "var", "power_reactive"),
    _f32("power_factor", 0x001E, "", "power_factor"),
    _f32("phase_angle", 0x0024, "°", "phase_angle"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "import_energy_active"),
    _f32("energy_export", 0x004A, "kWh", "export_energy_active"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "import_energy_reactive"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "export_energy_reactive"),
    _f32("demand_power", 0x0054, "W", "total_demand_power_active"),
    _f32("max_demand_power", 0x0056, "W", "maximum_total_demand_power_active"),
    _f32("import_demand_power", 0x0058, "W", "import_demand_power_active"),
    _f32("max_import_demand_power", 0x005A, "W", "maximum_import_demand_power_active"),
    _f32("export_demand_power", 0x005C, "W", "export_demand_power_active"),
    _f32("max_export_demand_power", 0x005E, "W", "maximum_export_demand_power_active"),
    _f32("current_demand", 0x0102, "A", "total_demand_current"),
    _f32("max_current_demand", 0x0108, "A", "maximum_total_demand_current"),
    _f32("energy_total", 0x0156, "kWh", "total_energy_active"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "total_energy_reactive"),
)

# class SDM72V2
SDM72V2 = (
    _f32("voltage_l1", 0x0000, "V", "l1_voltage"),
    _f32("voltage_l2", 0x0002, "V", "l2_voltage"),
    _f32("voltage_l3", 0x0004, "V", "l3_voltage"),
    _f32("current_l1", 0x0006, "A", "l1_current"),
    _f32("current_l2", 0x0008, "A", "l2_current"),
    _f32("current_l3", 0x000A, "A", "l3_current"),
    _f32("power_l1", 0x000C, "W", "l1_power_active"),
    _f32("power_l2", 0x000E, "W", "l2_power_active"),
    _f32("power_l3", 0x0010, "W", "l3_power_active"),
    _f32("apparent_power_l1", 0x0012, "VA", "l1_power_apparent"),
    _f32("apparent_power_l2", 0x0014, "VA", "l2_power_apparent"),
    _f32("apparent_power_l3", 0x0016, "VA", "l3_power_apparent"),
    _f32("reactive_power_l1", 0x0018, "var", "l1_power_reactive"),
    _f32("reactive_power_l2", 0x001A, "var", "l2_power_reactive"),
    _f32("reactive_power_l3", 0x001C, "var", "l3_power_reactive"),
    _f32("power_factor_l1", 0x001E, "", "l1_power_factor"),
    _f32("power_factor_l2", 0x0020, "", "l2_power_factor"),
    _f32("power_factor_l3", 0x0022, "", "l3_power_factor"),
    _f32("voltage_average", 0x002A, "V", "voltage_ln"),
    _f32("current_average", 0x002E, "A", "current_ln"),
    _f32("current_sum", 0x0030, "A", "total_line_current"),
    _f32("power", 0x0034, "W", "total_power"),
    _f32("power_factor", 0x003E, "", "total_pf"),
    _f32("apparent_power", 0x0038, "VA", "total_power_apparent"),
    _f32("reactive_power", 0x003C, "var", "total_power_reactive"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "import_energy_active"),
    _f32("energy_export", 0x004A, "kWh", "export_energy_active"),
    _f32("voltage_l1_l2", 0x00C8, "V", "l12_voltage"),
    _f32("voltage_l2_l3", 0x00CA, "V", "l23_voltage"),
    _f32("voltage_l3_l1", 0x00CC, "V", "l31_voltage"),
    _f32("voltage_line_average", 0x00CE, "V", "voltage_ll"),
    _f32("current_n", 0x00E0, "A", "neutral_current"),
    _f32("energy_total", 0x0156, "kWh", "total_energy_active"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "total_energy_reactive"),
    _f32("resettable_energy_total", 0x0180, "kWh", "resettable_total_energy_active"),
    _f32("resettable_energy_import", 0x0184, "kWh", "resettable_import_enerty_active"),
    _f32("resettable_energy_export", 0x0186, "kWh", "resettable_export_energy_active"),
    _f32("energy_net", 0x018C, "kWh", "net_kwh"),
    _f32("power_import", 0x0500, "W", "import_total_power_active"),
    _f32("power_export", 0x0502, "W", "export_total_power_active"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "eastron_sdm630": (
        SourceDefinition(
            device="eastron_sdm630",
            source=SOURCE,
            ref=REF,
            points=SDM630,
            notes=(
                STYLE,
                "it labels 0x56 'maximum import demand power (apparent)' in VA where the "
                "other sources and the SDM630 tables give the maximum total system power "
                "demand in W",
                "also lists 0x52 (total current, A) and 0xfe (a second total power factor), "
                "no library key",
            ),
        ),
    ),
    "eastron_sdm120": (
        SourceDefinition(
            device="eastron_sdm120", source=SOURCE, ref=REF, points=SDM120, notes=(STYLE,)
        ),
    ),
    "eastron_sdm230": (
        SourceDefinition(
            device="eastron_sdm230", source=SOURCE, ref=REF, points=SDM230, notes=(STYLE,)
        ),
    ),
    "eastron_sdm72d_m": (
        SourceDefinition(
            device="eastron_sdm72d_m",
            source=SOURCE,
            ref=REF,
            points=SDM72V2,
            notes=(
                STYLE,
                "class SDM72V2; its class SDM72 (v1) lists the same input registers",
            ),
        ),
    ),
}
