"""ABB Terra AC wallbox as evcc and the JernejHren/ABB-Terra-AC integration read it (facts
only). Holding registers, 32-bit values high word first.

Enums (charging state, socket lock, error labels) are not points: the harness compares
numbers. What each source reads of them is in its notes.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

JERNEJ = "JernejHren/ABB-Terra-AC@2610e6b275f9d694d142f76f0580af0b7f7d7cc2"


def _p(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# charger/abb.go: each value read on its own, u32 big-endian
EVCC_TERRA = (
    _p("max_current", 0x4006, "u32", "A", 0.001, "abbRegMaxRated"),
    _p("error_code_raw", 0x4008, "u32", "", 1.0, "abbRegErrorCode"),
    _p("current_limit", 0x400E, "u32", "A", 0.001, "abbRegGetCurrent"),
    _p("current_l1", 0x4010, "u32", "A", 0.001, "abbRegCurrents"),
    _p("current_l2", 0x4012, "u32", "A", 0.001, "abbRegCurrents+2"),
    _p("current_l3", 0x4014, "u32", "A", 0.001, "abbRegCurrents+4"),
    _p("voltage_l1", 0x4016, "u32", "V", 0.1, "abbRegVoltages"),
    _p("voltage_l2", 0x4018, "u32", "V", 0.1, "abbRegVoltages+2"),
    _p("voltage_l3", 0x401A, "u32", "V", 0.1, "abbRegVoltages+4"),
    _p("power", 0x401C, "u32", "W", 1.0, "abbRegPower"),
    _p("session_energy", 0x401E, "u32", "kWh", 0.001, "abbRegEnergy"),
)

# custom_components/abb_terra_ac/__init__.py: one read of 37 registers from 0x4000
JERNEJ_TERRA = (
    _p("max_current", 0x4006, "u32", "A", 0.001, "user_settable_max_current"),
    _p("error_code_raw", 0x4008, "u16", "", 1.0, "error_code"),
    _p("current_limit", 0x400E, "u32", "A", 0.001, "charging_current_limit"),
    _p("current_l1", 0x4010, "u32", "A", 0.001, "charging_current_l1"),
    _p("current_l2", 0x4012, "u32", "A", 0.001, "charging_current_l2"),
    _p("current_l3", 0x4014, "u32", "A", 0.001, "charging_current_l3"),
    _p("voltage_l1", 0x4016, "u32", "V", 0.1, "voltage_l1"),
    _p("voltage_l2", 0x4018, "u32", "V", 0.1, "voltage_l2"),
    _p("voltage_l3", 0x401A, "u32", "V", 0.1, "voltage_l3"),
    _p("power", 0x401C, "u32", "W", 1.0, "active_power"),
    _p("session_energy", 0x401E, "u32", "Wh", 1.0, "energy_delivered"),
    _p("communication_timeout", 0x4020, "u16", "s", 1.0, "communication_timeout"),
    _p("current_limit_setpoint", 0x4022, "u32", "A", 0.001, "charging_current_limit_modbus"),
    _p("fallback_current", 0x4024, "u16", "A", 1.0, "fallback_limit"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "abb_terra_ac": (
        SourceDefinition(
            device="abb_terra_ac",
            source="evcc",
            ref=f"{EVCC}:charger/abb.go",
            points=EVCC_TERRA,
            notes=(
                "charging state: reads 0x400c as two registers and keeps the third byte (the "
                "high byte of 0x400d) masked with 0x7f: 0 A, 1 B1, 2 B2, 3 C1, 4 C2, 5 other "
                "(then the socket lock state >= 0x0101 tells B from A)",
                "writes the current limit as u32 mA at 0x4100 (FC16), 0 to disable; the "
                "mapping's write_address of current_limit_setpoint",
                "start/stop 0x4105 and phase switching 0x4102 ('not supported') are only "
                "named in comments",
                "a status read every 30 s as a keep-alive; requires firmware >= 1.6.5 (template)",
            ),
        ),
        SourceDefinition(
            device="abb_terra_ac",
            source="community:JernejHren/ABB-Terra-AC",
            ref=f"{JERNEJ}:custom_components/abb_terra_ac/__init__.py",
            points=JERNEJ_TERRA,
            notes=(
                "reads 0x4000-0x4024 in one request of 37 registers (Modbus TCP)",
                "charging state: the high byte of 0x400d, low nibble only (0-5 as the "
                "document); it notes 0x400c always reads 0",
                "error code: 0x4008 alone, as u16, with the labels 2, 4, 8, ... 0x4000 of "
                "the user manual",
                "socket lock 0x400a u32: 0, 1, 0x11, 0x101, 0x111 (as the document)",
                "writes: current limit u32 mA at 0x4100 (FC16, number.py), fallback 0x4109 "
                "(FC06), cable lock 0x4103 1/0 (switch.py), start 0 / stop 1 at 0x4105 "
                "(button.py)",
                "reports a firmware bug: after an unexpected reboot 0x4022 reads 32 A and "
                "0x4024 reads 256; it writes the last good values back",
            ),
        ),
    ),
}
