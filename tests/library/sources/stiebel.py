"""Stiebel Eltron WPM heat pump managers through the ISG, as pystiebeleltron and evcc read
them (facts only).

pystiebeleltron (ThyMYthOS/python-stiebel-eltron, the library Home Assistant's Stiebel
integrations use; pail23/python-stiebel-eltron is its fork, not another source) generates
its register map from CSV rows copied from Stiebel's Modbus document, one-based, and
subtracts one for the wire. Its kWh + MWh energy pairs (read as two registers, summed
with weights 1 and 1000) and its enum rows (operating mode, controller id, SG-ready state)
have no shape here and are named in the notes; the flow rate (l/min) is left out because
the mapping gives it in Home Assistant's spelling, L/min.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

PYSTIEBEL = "ThyMYthOS/python-stiebel-eltron@b1c59ba3cb9fcadb1121efcf23b96504108c421b"


def _in(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, type_, unit, scale, name=name)


def _hold(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# pystiebeleltron/wpm.py (generated): gauge = signed 16-bit x scale, integer(signed=False)
# = u16; wire addresses (the CSV's one-based number minus one)
PYSTIEBEL_WPM = (
    _in("outdoor_temperature", 506, "s16", "°C", 0.1, "outside_temperature"),
    _in("temperature_hc1", 507, "s16", "°C", 0.1, "actual_temperature_hk_1"),
    _in("set_temperature_hc1", 509, "s16", "°C", 0.1, "set_temperature_hk_1"),
    _in("temperature_hc2", 510, "s16", "°C", 0.1, "actual_temperature_hk_2"),
    _in("set_temperature_hc2", 511, "s16", "°C", 0.1, "set_temperature_hk_2"),
    _in("heat_pump_flow_temperature", 512, "s16", "°C", 0.1, "actual_flow_temperature_wp"),
    _in("flow_temperature", 514, "s16", "°C", 0.1, "actual_flow_temperature"),
    _in("return_temperature", 515, "s16", "°C", 0.1, "actual_return_temperature"),
    _in("buffer_temperature", 517, "s16", "°C", 0.1, "actual_buffer_temperature"),
    _in("buffer_set_temperature", 518, "s16", "°C", 0.1, "set_buffer_temperature"),
    _in("heating_pressure", 519, "s16", "bar", 0.01, "heating_pressure"),
    _in("hot_water_temperature", 521, "s16", "°C", 0.1, "actual_temperature_dhw"),
    _in("hot_water_set_temperature", 522, "s16", "°C", 0.1, "set_temperature_dhw"),
    _in("source_temperature", 535, "s16", "°C", 0.1, "source_temperature"),
    _in("operating_status", 2500, "u16", "", 1.0, "operating_status"),
    _in("bus_status", 2504, "u16", "", 1.0, "bus_status"),
    _in("error_number", 2506, "u16", "", 1.0, "active_error"),
    _hold("comfort_temperature_hc1", 1501, "s16", "°C", 0.1, "comfort_temperature_hk_1"),
    _hold("eco_temperature_hc1", 1502, "s16", "°C", 0.1, "eco_temperature_hk_1"),
    _hold("heating_curve_rise_hc1", 1503, "s16", "", 0.01, "heating_curve_rise_hk_1"),
    _hold("hot_water_comfort_temperature", 1509, "s16", "°C", 0.1, "comfort_temperature_dhw"),
    _hold("hot_water_eco_temperature", 1510, "s16", "°C", 0.1, "eco_temperature_dhw"),
)

# templates/definition/charger/stiebel-wpm.yaml (sgready): temp by tempsource
EVCC_WPM = (
    _in("hot_water_temperature", 521, "s16", "°C", 0.1, "temp (warmwater)"),
    _in("buffer_temperature", 517, "s16", "°C", 0.1, "temp (buffer)"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "stiebel_isg": (
        SourceDefinition(
            device="stiebel_isg",
            source="community:ThyMYthOS/python-stiebel-eltron",
            ref=f"{PYSTIEBEL}:pystiebeleltron/wpm.py",
            points=PYSTIEBEL_WPM,
            notes=(
                "api/README.md: rows copied by hand from Stiebel's Modbus document, "
                "one-based; the generator subtracts one for the wire address",
                "0x8000 is the ISG's 'unavailable' answer on every field",
                "set temperature HK 1 read at 510 (one-based) on every controller: the row "
                "notes a WPM 3i answers there, not at the 509 the document prints for it",
                "energy totals: kWh register (0-999) then MWh register, summed with weights "
                "1 and 1000 (heating 3502/3503, hot water 3505/3506, booster 3507/3508 and "
                "3509/3510, consumed 3512/3513 and 3515/3516, one-based)",
                "operating mode holding 1501 (one-based) 0-5: emergency, ready, program, "
                "comfort, eco, water heating (the Home Assistant component's labels); "
                "operating status 2501 bits 0-9: pump HK1, pump HK2, heat-up program, "
                "booster stages, heating, hot water, compressor, summer mode, cooling, "
                "defrost",
                "controller identification 5002 (one-based): 390 WPM 3, 391 WPM 3i, "
                "449 WPMsystem, 103/104/551 LWZ",
                "heating flow rate 521 (one-based) x0.01 l/min, not compared (unit spelling)",
            ),
        ),
        SourceDefinition(
            device="stiebel_isg",
            source="evcc",
            ref=f"{EVCC}:templates/definition/charger/stiebel-wpm.yaml",
            points=EVCC_WPM,
            notes=(
                "reads the SG-ready state at wire 5000 (1 frost protection, 2 normal, "
                "3 forced operation, 4 immediate control)",
                "writes wire 4001 and 4002 (SG-ready inputs 1 and 2, one-based 4002/4003) "
                "with function 06: 0/0 normal, 1/0 boost, 0/1 dim",
            ),
        ),
    ),
}
