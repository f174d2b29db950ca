"""The Victron GX device's system service (unit 100) as independent sources read it.

sfstar/hass-victron (a Home Assistant integration carrying the whole register list as
data), evcc (templates/definition/meter/victron-energy.yaml) and openWB
(packages/modules/devices/victron/victron). Victron's own dbus-modbus-client reads other
makers' devices for the GX, not the GX's server: it is no source here. Enums and switches
are not compared (the cross-check compares numbers); the points below are the numeric
ones. hass-victron's "scale" is Victron's divisor: the scale here is its inverse.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

HASS_VICTRON = "sfstar/hass-victron@3d3ec1e6cb7768d3c6d49ed23e9b52814477c205"
OPENWB = "openWB/core@3039a21010759129b7dd182df0e7e183fed28baa"


def _h(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    return SourcePoint(key, "holding", address, kind, unit, scale, name=name)


def _i(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    return SourcePoint(key, "input", address, kind, unit, scale, name=name)


# custom_components/victron/const.py: system_*, settings_* and settings_ess_* registers
HASS_VICTRON_SYSTEM = (
    _h("pv_ac_output_power_l1", 808, "u16", "W", name="system_pvonoutput_L1"),
    _h("pv_ac_output_power_l2", 809, "u16", "W", name="system_pvonoutput_L2"),
    _h("pv_ac_output_power_l3", 810, "u16", "W", name="system_pvonoutput_L3"),
    _h("pv_ac_input_power_l1", 811, "u16", "W", name="system_pvongrid_L1"),
    _h("pv_ac_input_power_l2", 812, "u16", "W", name="system_pvongrid_L2"),
    _h("pv_ac_input_power_l3", 813, "u16", "W", name="system_pvongrid_L3"),
    _h("pv_genset_power_l1", 814, "u16", "W", name="system_pvongenset_L1"),
    _h("pv_genset_power_l2", 815, "u16", "W", name="system_pvongenset_L2"),
    _h("pv_genset_power_l3", 816, "u16", "W", name="system_pvongenset_L3"),
    _h("consumption_power_l1", 817, "u16", "W", name="system_consumption_L1"),
    _h("consumption_power_l2", 818, "u16", "W", name="system_consumption_L2"),
    _h("consumption_power_l3", 819, "u16", "W", name="system_consumption_L3"),
    _h("grid_power_l1", 820, "s16", "W", name="system_grid_L1"),
    _h("grid_power_l2", 821, "s16", "W", name="system_grid_L2"),
    _h("grid_power_l3", 822, "s16", "W", name="system_grid_L3"),
    _h("genset_power_l1", 823, "s16", "W", name="system_genset_L1"),
    _h("genset_power_l2", 824, "s16", "W", name="system_genset_L2"),
    _h("genset_power_l3", 825, "s16", "W", name="system_genset_L3"),
    _h("firmware_major", 834, "u16", "", name="system_firmware_gx_major_version"),
    _h("firmware_beta", 835, "u16", "", name="system_firmware_gx_beta_release"),
    _h("battery_voltage", 840, "u16", "V", 0.1, name="system_battery_voltage"),
    _h("battery_current", 841, "s16", "A", 0.1, name="system_battery_current"),
    _h("battery_power", 842, "s16", "W", name="system_battery_power"),
    _h("battery_soc", 843, "u16", "%", name="system_battery_soc"),
    _h("battery_time_to_go", 846, "u16", "s", 100.0, name="system_battery_time_to_go"),
    _h("pv_dc_power", 850, "u16", "W", name="system_dc_pv_power"),
    _h("pv_dc_current", 851, "s16", "A", 0.1, name="system_dc_pv_current"),
    _h("charger_power", 855, "u16", "W", name="system_charger_power"),
    _h("dc_system_power", 860, "s16", "W", name="system_system_power"),
    _h("vebus_charge_current", 865, "s16", "A", 0.1, name="system_bus_charge_current"),
    _h("vebus_charge_power", 866, "s16", "W", name="system_bus_charge_power"),
    _h("ess_grid_setpoint", 2700, "s16", "W", name="settings_ess_acpowersetpoint"),
    _h("ess_max_charge_percentage", 2701, "u16", "%", name="settings_ess_maxchargepercentage"),
    _h(
        "ess_max_discharge_percentage", 2702, "u16", "%", name="settings_ess_maxdischargepercentage"
    ),
    _h("max_discharge_power", 2704, "u16", "W", 10.0, name="settings_ess_maxdischargepower"),
    _h("max_charge_current", 2705, "s16", "A", name="settings_ess_maxchargecurrent"),
    _h("max_feed_in_power", 2706, "s16", "W", 100.0, name="settings_ess_maxfeedinpower"),
    _h("grid_setpoint_override", 2716, "s32", "W", name="settings_overrides_setpoint_volatile"),
    _h("ess_minimum_soc", 2901, "u16", "%", 0.1, name="settings_ess_batterylife_minimumsoc"),
    _h("batterylife_soc_limit", 2903, "u16", "%", 0.1, name="settings_ess_batterylife_soclimit"),
)

# templates/definition/meter/victron-energy.yaml: unit 100, "type: input" (function 4)
EVCC_VICTRON = (
    _i("pv_ac_output_power_l1", 808, "u16", "W", name="ACout pv power L1"),
    _i("pv_ac_output_power_l2", 809, "u16", "W", name="ACout pv power L2"),
    _i("pv_ac_output_power_l3", 810, "u16", "W", name="ACout pv power L3"),
    _i("pv_ac_input_power_l1", 811, "u16", "W", name="ACin pv power L1"),
    _i("pv_ac_input_power_l2", 812, "u16", "W", name="ACin pv power L2"),
    _i("pv_ac_input_power_l3", 813, "u16", "W", name="ACin pv power L3"),
    _i("grid_power_l1", 820, "s16", "W", name="L1 grid power"),
    _i("grid_power_l2", 821, "s16", "W", name="L2 grid power"),
    _i("grid_power_l3", 822, "s16", "W", name="L3 grid power"),
    _i("battery_power", 842, "s16", "W", name="active DC power"),
    _i("battery_soc", 843, "u16", "%", name="Soc"),
    _i("pv_dc_power", 850, "u16", "W", name="DC pv power"),
    _h("ess_minimum_soc", 2901, "u16", "%", 0.1, name="limit soc"),
)

# packages/modules/devices/victron/victron/{counter,bat,inverter}.py: holding (function 3)
OPENWB_VICTRON = (
    _h("pv_ac_output_power_l1", 808, "u16", "W", name="inverter 808+0"),
    _h("pv_ac_output_power_l2", 809, "u16", "W", name="inverter 808+1"),
    _h("pv_ac_output_power_l3", 810, "u16", "W", name="inverter 808+2"),
    _h("pv_ac_input_power_l1", 811, "u16", "W", name="inverter 808+3"),
    _h("pv_ac_input_power_l2", 812, "u16", "W", name="inverter 808+4"),
    _h("pv_ac_input_power_l3", 813, "u16", "W", name="inverter 808+5"),
    _h("grid_power_l1", 820, "s16", "W", name="counter powers[0]"),
    _h("grid_power_l2", 821, "s16", "W", name="counter powers[1]"),
    _h("grid_power_l3", 822, "s16", "W", name="counter powers[2]"),
    _h("battery_power", 842, "s16", "W", name="bat power"),
    _h("battery_soc", 843, "u16", "%", name="bat soc"),
    _h("pv_dc_power", 850, "u16", "W", name="inverter 850"),
    _h("ess_max_discharge_percentage", 2702, "u16", "%", name="bat write 2702"),
    _h("grid_setpoint_override", 2716, "s32", "W", name="bat write 2716"),
)

GX_SYSTEM = (
    SourceDefinition(
        device="victron_gx_system",
        source="community:sfstar/hass-victron",
        ref=f"{HASS_VICTRON}:custom_components/victron/const.py",
        points=HASS_VICTRON_SYSTEM,
        notes=(
            "the repository also keeps Victron's register list itself "
            "(resources/CCGX-Modbus-TCP-register-list-3.50.xlsx and -3.66.xlsx), the "
            "mapping's document",
            "reads holding registers at the unit the user gives (100 for the system service)",
            "2704 (max discharge power) is read as uint16; the register list prints int16",
            "845 (consumed amp-hours) has divisor -10, as in the list: not transcribed (a "
            "source scale here is positive), the mapping's scale -0.1 is the same",
            "2902 (ESS mode) is a select whose labels 0-3 are BatteryLife's modes "
            "(self-consumption with BatteryLife, self-consumption, keep charged, external "
            "control), where the list gives 1 = with phase compensation, 2 = without, "
            "3 = external control",
            "2703 (set point x100 W) is read too, as a duplicate of 2700; the mapping leaves it out",
        ),
    ),
    SourceDefinition(
        device="victron_gx_system",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/victron-energy.yaml",
        points=EVCC_VICTRON,
        notes=(
            "reads with function 4 (input) at unit 100; the GX answers 3 and 4 alike",
            "battery power 842 gets scale -1 (evcc counts discharge positive); transcribed "
            "with the register's own scale 1",
            "pv: the sum of 808-813 and 850; grid: the sum of 820-822",
            "writes the battery's minimum SoC (limitsoc) to 2901 as value x10 (function 6)",
        ),
    ),
    SourceDefinition(
        device="victron_gx_system",
        source="openwb",
        ref=f"{OPENWB}:packages/modules/devices/victron/victron/bat.py",
        points=OPENWB_VICTRON,
        notes=(
            "bat.py reads 842/843 and writes 2902 (mode 2), 2702 (0 or 100 %) and 2716 "
            "(int32 grid set point), after reading 5400 (Dynamic ESS active)",
            "counter.py reads 820-822 (int16 block); inverter.py reads 808-813 (uint16 "
            "block) and 850 at unit 100 and negates their sum",
        ),
    ),
)

DEFINITIONS = {"victron_gx_system": GX_SYSTEM}
