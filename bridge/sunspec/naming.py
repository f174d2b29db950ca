"""How a SunSpec point is named and presented: its entity key, its human name, its unit
and Home Assistant classes. Pure tables and string rules; ``mapping`` uses them.

Keys: the model's name, the path of groups (a repeating group with its 1-based index)
and the point's name, lowercase snake (``mppt_module_2_dcw``): stable for a device
whatever values it reads. Names: the point's label in sentence case, after its groups'
("Module 2 DC power"; a module's own ``IDStr`` instead of "Module 2" when it is known).

Units: SunSpec writes ``C``, ``Secs``, ``Pct``, ``cos()``; Home Assistant wants ``°C``,
``s``, ``%`` and no unit for a power factor. ``presentation`` turns a unit into the one
Home Assistant takes and the device class that goes with it; a unit it has no class for
stays as SunSpec writes it, without a class.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from bridge.core.convention import ABBREVIATIONS

_CAMEL = re.compile(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])")
_NOT_KEY = re.compile(r"[^a-z0-9]+")


def snake(text: str) -> str:
    """``DERMeasureAC`` -> ``der_measure_ac``, ``lithium-ion-module`` ->
    ``lithium_ion_module``: a key part (a-z, 0-9, _)."""
    return _NOT_KEY.sub("_", _CAMEL.sub("_", text).lower()).strip("_") or "x"


def point_part(name: str) -> str:
    """A point's name as a key part: lowercased as it is (``DCW`` -> ``dcw``, ``PhVphA``
    -> ``phvpha``): SunSpec's abbreviations are not camel-case words."""
    return _NOT_KEY.sub("_", name.lower()).strip("_") or "x"


def key_of(prefix: str, path: tuple[tuple[str, int], ...], name: str) -> str:
    """The entity key of a point: model prefix, groups (with the instance of a repeating
    one), point name."""
    parts = [prefix]
    for group, index in path:
        parts.append(snake(group))
        if index:
            parts.append(str(index))
    parts.append(point_part(name))
    return "_".join(parts)


def group_label(label: str) -> str:
    """A repeating group's label as one instance's: ``Stored Curve Points`` -> ``Curve
    point`` (before its index)."""
    words = label.removeprefix("Stored ").split()
    if words and len(words[-1]) > 3 and words[-1].endswith("s") and not words[-1].endswith("ss"):
        words[-1] = words[-1][:-1]
    return " ".join(words)


def sentence(label: str) -> str:
    """``DC Power`` -> ``DC power``, ``Watts`` -> ``Watts``: words with two capitals or a
    digit (abbreviations, codes) kept, the others lowercased after the first."""
    words = label.replace("_", " ").split()
    shown = [
        w if i == 0 or sum(c.isupper() for c in w) > 1 or any(c.isdigit() for c in w) else w.lower()
        for i, w in enumerate(words)
    ]
    name = " ".join(shown)
    return name[:1].upper() + name[1:]


# capitals kept in a symbol's name (GROUND_FAULT, DC_OVER_VOLT) besides the library's own
_SHORT = ABBREVIATIONS | {"AC", "DC", "HW", "PV", "ID", "IP", "SOC", "SOH", "BMS", "GFDI", "RTC"}


def symbol_label(name: str) -> str:
    """An enum or bit symbol's name as words: ``DC_OVER_VOLT`` -> ``DC over volt``."""
    words = [w for w in name.replace("-", "_").split("_") if w]
    shown = [w.upper() if w.upper() in _SHORT else w.lower() for w in words]
    return " ".join(shown)[:1].upper() + " ".join(shown)[1:] if shown else name


@dataclass(frozen=True, slots=True)
class Presentation:
    """A unit as Home Assistant takes it, its device class, and whether it is a counter
    (``total_increasing``) or a measurement."""

    unit: str | None
    device_class: str | None
    state_class: str | None


# SunSpec unit -> (Home Assistant unit, device class); classes need the units in
# bridge/core/hass.py SENSOR_UNITS
_UNITS: dict[str, tuple[str | None, str | None]] = {
    "W": ("W", "power"),
    "VA": ("VA", "apparent_power"),
    "var": ("var", "reactive_power"),
    "Var": ("var", "reactive_power"),
    "VAr": ("var", "reactive_power"),
    "V": ("V", "voltage"),
    "A": ("A", "current"),
    "Hz": ("Hz", "frequency"),
    "C": ("°C", "temperature"),
    "Wh": ("Wh", "energy"),
    "WH": ("Wh", "energy"),
    "kWh": ("kWh", "energy"),
    "varh": ("varh", "reactive_energy"),
    "Varh": ("varh", "reactive_energy"),
    "VAh": ("VAh", None),
    "Ah": ("Ah", None),
    "AH": ("Ah", None),
    "Secs": ("s", "duration"),
    "Sec": ("s", "duration"),
    "mSecs": ("ms", "duration"),
    "Pct": ("%", None),
    "%": ("%", None),
    "PF": (None, "power_factor"),
    "cos()": (None, "power_factor"),
    "Degrees": ("°", None),
    "deg": ("°", None),
    "HPa": ("hPa", "atmospheric_pressure"),
    "W/m2": ("W/m²", None),
    "W/m^2": ("W/m²", None),
    "mps": ("m/s", None),
    "ohms": ("Ω", None),
}


def _relative(units: str) -> str | None:
    """A unit SunSpec writes relative to a reference (``% WMax``, ``VNomPct``, ``% WMax/
    min``) as a percentage (per minute, per second); ``DeptRef`` (a curve's dependent
    reference, whose unit another point chooses) as none; any other as it is."""
    if units == "DeptRef" or not units:
        return None
    if units.startswith("%") or "Pct" in units:
        rate = units.rpartition("/")[2].lower() if "/" in units else ""
        return "%" + {"min": "/min", "sec": "/s", "s": "/s"}.get(rate, "")
    return units


_TOTALS = frozenset({"energy", "reactive_energy"})  # Home Assistant sums these only


def presentation(units: str, counter: bool, number: bool) -> Presentation:
    """How a point with SunSpec ``units`` is shown: ``counter`` for an accumulator (or an
    energy total), ``number`` False for an enum, bitfield or text (no unit, no class)."""
    if not number:
        return Presentation(None, None, None)
    unit, device_class = _UNITS.get(units.strip(), (_relative(units.strip()), None))
    if device_class in _TOTALS and not counter:
        # a rating or a setting in Wh is not summed: energy held, or no class at all
        device_class = "energy_storage" if device_class == "energy" else None
    state_class = (
        "total_increasing" if counter else ("measurement" if unit or device_class else None)
    )
    return Presentation(unit, device_class, state_class)
