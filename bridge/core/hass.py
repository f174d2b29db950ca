"""Home Assistant's rules for device classes, units and state classes (as of HA 2025.x).

A discovery payload that breaks these makes Home Assistant log an error or a warning and
drop the unit or the entity, so mappings are checked against them when they load. The
tables hold the device classes a Modbus device can plausibly use; others are refused
with the list of known ones, so a new one is added here on purpose.
"""

from __future__ import annotations

from bridge.core.entity import Component, Entity

_PRESSURE = frozenset({"Pa", "hPa", "kPa", "bar", "cbar", "mbar", "mmHg", "inHg", "psi", "mPa"})
_ENERGY = frozenset(
    {"J", "kJ", "MJ", "GJ", "mWh", "Wh", "kWh", "MWh", "GWh", "TWh", "cal", "kcal", "Mcal", "Gcal"}
)
_VOLUME = frozenset({"L", "mL", "gal", "fl. oz.", "m³", "ft³", "CCF"})

SENSOR_UNITS: dict[str, frozenset[str | None]] = {
    "apparent_power": frozenset({"mVA", "VA", "kVA"}),
    "atmospheric_pressure": frozenset(_PRESSURE),
    "battery": frozenset({"%"}),
    "current": frozenset({"A", "mA"}),
    "distance": frozenset({"km", "m", "cm", "mm", "mi", "nmi", "yd", "in", "ft"}),
    "duration": frozenset({"d", "h", "min", "s", "ms", "µs"}),
    "energy": frozenset(_ENERGY),
    "energy_storage": frozenset(_ENERGY),
    "frequency": frozenset({"Hz", "kHz", "MHz", "GHz"}),
    "humidity": frozenset({"%"}),
    "power": frozenset({"mW", "W", "kW", "MW", "GW", "TW", "BTU/h"}),
    "power_factor": frozenset({"%", None}),
    "pressure": frozenset(_PRESSURE),
    "reactive_energy": frozenset({"varh", "kvarh"}),
    "reactive_power": frozenset({"mvar", "var", "kvar"}),
    "signal_strength": frozenset({"dB", "dBm"}),
    "temperature": frozenset({"°C", "°F", "K"}),
    "voltage": frozenset({"µV", "mV", "V", "kV", "MV"}),
    "volume": frozenset(_VOLUME),
    "volume_flow_rate": frozenset(
        {
            "m³/h",
            "m³/min",
            "m³/s",
            "ft³/min",
            "L/h",
            "L/min",
            "L/s",
            "gal/h",
            "gal/min",
            "mL/s",
            "gal/d",
        }
    ),
    "volume_storage": frozenset(_VOLUME),
    "water": frozenset({"L", "gal", "m³", "ft³", "CCF"}),
}

_TOTALS = frozenset({"total", "total_increasing"})
_ALL_STATE_CLASSES = frozenset({"measurement", "total", "total_increasing"})
STATE_CLASSES: dict[str, frozenset[str]] = {
    "energy": _TOTALS,
    "energy_storage": frozenset({"measurement"}),
    "reactive_energy": _TOTALS,
    "volume": _TOTALS,
    "water": _TOTALS,
    "volume_storage": frozenset({"measurement"}),
}

BINARY_SENSOR_CLASSES = frozenset(
    {
        "battery",
        "battery_charging",
        "carbon_monoxide",
        "cold",
        "connectivity",
        "door",
        "garage_door",
        "gas",
        "heat",
        "light",
        "lock",
        "moisture",
        "motion",
        "moving",
        "occupancy",
        "opening",
        "plug",
        "power",
        "presence",
        "problem",
        "running",
        "safety",
        "smoke",
        "sound",
        "tamper",
        "update",
        "vibration",
        "window",
    }
)
# What Home Assistant shows (in English) for a binary sensor that is off and on, by its
# device class (homeassistant/components/binary_sensor/strings.json); None: no class.
BINARY_SENSOR_STATES: dict[str | None, tuple[str, str]] = {
    None: ("Off", "On"),
    "battery": ("Normal", "Low"),
    "battery_charging": ("Not charging", "Charging"),
    "carbon_monoxide": ("Clear", "Detected"),
    "cold": ("Normal", "Cold"),
    "connectivity": ("Disconnected", "Connected"),
    "door": ("Closed", "Open"),
    "garage_door": ("Closed", "Open"),
    "gas": ("Clear", "Detected"),
    "heat": ("Normal", "Hot"),
    "light": ("No light", "Light detected"),
    "lock": ("Locked", "Unlocked"),
    "moisture": ("Dry", "Wet"),
    "motion": ("Clear", "Detected"),
    "moving": ("Not moving", "Moving"),
    "occupancy": ("Clear", "Detected"),
    "opening": ("Closed", "Open"),
    "plug": ("Unplugged", "Plugged in"),
    "power": ("Off", "On"),
    "presence": ("Away", "Home"),
    "problem": ("OK", "Problem"),
    "running": ("Not running", "Running"),
    "safety": ("Safe", "Unsafe"),
    "smoke": ("Clear", "Detected"),
    "sound": ("Clear", "Detected"),
    "tamper": ("Clear", "Tampering detected"),
    "update": ("Up-to-date", "Update available"),
    "vibration": ("Clear", "Detected"),
    "window": ("Closed", "Open"),
}
SWITCH_CLASSES = frozenset({"outlet", "switch"})
BUTTON_CLASSES = frozenset({"identify", "restart", "update"})


# What the energy dashboard takes for an energy counter (homeassistant/components/energy/
# validate.py): a kWh counter in J or cal would load as a sensor but not as a source.
ENERGY_DASHBOARD_UNITS = frozenset({"Wh", "kWh", "MWh", "GWh", "MJ", "GJ"})
COUNTER_STATE_CLASSES = frozenset({"total", "total_increasing"})
_ALWAYS_COUNTED = frozenset({"energy", "gas", "water"})  # classes HA only sums


def binary_sensor_class(entity: Entity) -> str | None:
    """The device class a binary sensor is published with: its own where binary sensors
    take it (a switch's class does not carry over to it shown read-only), ``problem`` for
    an alarm, else none."""
    device_class = entity.ha.device_class
    if device_class in BINARY_SENSOR_CLASSES:
        return device_class
    return "problem" if entity.alarm else None


def presentation_problems(entity: Entity) -> list[str]:
    """What Home Assistant would refuse in this entity's presentation (empty when fine)."""
    return _component_problems(entity) + counter_problems(entity)


def counter_problems(entity: Entity) -> list[str]:
    """What keeps a counter out of Home Assistant's statistics or energy dashboard: a
    counter (an energy meter, a simulated rise per hour, a reset confirmation) without a
    summing state class, an energy unit the dashboard refuses (a summed value that is not
    a number is refused with the state classes)."""
    state_class = entity.ha.state_class
    counted = state_class in COUNTER_STATE_CLASSES
    device_class = entity.ha.device_class
    if not entity.readable:
        return []
    looks_counted = (
        device_class in _ALWAYS_COUNTED
        or entity.confirm_reset is not None
        or (entity.simulate is not None and entity.simulate.per_hour is not None)
    )
    if looks_counted and not counted:
        return [
            "a counter needs state_class total_increasing (or total where the device resets "
            "it by design): without one Home Assistant keeps no statistics of it"
        ]
    if counted and device_class == "energy" and entity.unit not in ENERGY_DASHBOARD_UNITS:
        shown = ", ".join(sorted(ENERGY_DASHBOARD_UNITS))
        return [f"unit {entity.unit!r} is not one the energy dashboard takes ({shown})"]
    return []


def _component_problems(entity: Entity) -> list[str]:
    component = entity.component
    device_class = entity.ha.device_class
    if component in (Component.SENSOR, Component.NUMBER):
        return _numeric_problems(entity, device_class)
    allowed = {
        Component.BINARY_SENSOR: BINARY_SENSOR_CLASSES,
        Component.SWITCH: SWITCH_CLASSES,
        Component.BUTTON: BUTTON_CLASSES,
    }.get(component, frozenset())
    if device_class is not None and device_class not in allowed:
        known = ", ".join(sorted(allowed)) or "none"
        return [f"device_class {device_class!r} is not one of {component.value}'s ({known})"]
    return []


def _numeric_problems(entity: Entity, device_class: str | None) -> list[str]:
    problems: list[str] = []
    if entity.kind != "number":
        if device_class is not None:
            problems.append("an enum or text entity takes no device_class (the bridge sets it)")
        return problems
    if device_class is None:
        return problems
    units = SENSOR_UNITS.get(device_class)
    if units is None:
        return [f"unknown device_class {device_class!r} (known: {', '.join(sorted(SENSOR_UNITS))})"]
    if entity.unit_from is not None:
        problems.append("a unit read from a register can change category: leave device_class out")
    elif entity.unit not in units:
        shown = ", ".join(sorted(str(u) for u in units))
        problems.append(
            f"unit {entity.unit!r} is not valid for device_class {device_class} ({shown})"
        )
    state_class = entity.ha.state_class
    allowed = STATE_CLASSES.get(device_class, _ALL_STATE_CLASSES)
    if state_class is not None and state_class not in allowed:
        problems.append(
            f"state_class {state_class!r} is impossible for device_class {device_class}"
        )
    return problems
