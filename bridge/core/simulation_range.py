"""Where a simulated value lives: one table by unit and device class, refined by words of
the key, overridden by the entity's own ``simulate:`` hint in its mapping.

``plausible(point)`` says the range a simulated measurement moves in and its typical
value (a battery of a 24 V genset near 27 V, a mains voltage near 230 V, a line voltage
near 400 V, phase angles 0/120/240°), or for a counter its typical reading and how much it
rises per running hour (run hours by the hour, starts rarely, energy by the simulated
power: ``energy_source``). None where nothing plausible is known (a raw word, a count
without a unit): those keep the range of their register.
"""

from __future__ import annotations

from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass, replace

from bridge.core.mapping import Point

COUNTER_CLASSES = ("total", "total_increasing")
_RUN_HOURS = 1250.0  # the age of a simulated machine


@dataclass(frozen=True, slots=True)
class Plausible:
    """A value's plausible range and typical reading; a counter's rise per hour."""

    low: float
    high: float
    typical: float
    per_hour: float = 0.0


_MEASURED: dict[str, Plausible] = {  # by unit
    "V": Plausible(215, 245, 230),
    "Hz": Plausible(49, 51, 50),
    "A": Plausible(8, 16, 12),
    "W": Plausible(800, 2200, 1500),
    "kW": Plausible(5, 25, 15),
    "kvar": Plausible(1, 8, 4),
    "kVA": Plausible(6, 28, 16),
    "var": Plausible(100, 600, 300),  # a household meter's reactive and apparent power
    "VA": Plausible(900, 2400, 1600),
    "°C": Plausible(30, 85, 40),
    "%": Plausible(20, 80, 50),
    "rpm": Plausible(1440, 1520, 1480),
    "kPa": Plausible(250, 450, 350),
    "bar": Plausible(2, 6, 3),
    "Ω": Plausible(80, 160, 120),
}
_VOLTAGES = (  # words of the key -> the voltage it is (a 24 V genset battery, a 400 V drive)
    (frozenset({"battery"}), Plausible(24.5, 28.0, 26.8)),
    (frozenset({"charger"}), Plausible(26.0, 28.8, 27.6)),
    (frozenset({"dc", "bus", "link"}), Plausible(520, 600, 540)),
    (frozenset({"uab", "ubc", "uca", "line"}), Plausible(390, 410, 400)),
)
_COUNTED: dict[str | None, Plausible] = {  # by unit: typical reading, rise per hour
    "h": Plausible(0, 1e9, _RUN_HOURS, 1),
    "min": Plausible(0, 1e9, _RUN_HOURS * 60, 60),
    "s": Plausible(0, 1e12, _RUN_HOURS * 3600, 3600),
    "kWh": Plausible(0, 1e12, _RUN_HOURS * 12, 15),
    "Wh": Plausible(0, 1e12, _RUN_HOURS * 1200, 1500),
    "MWh": Plausible(0, 1e9, _RUN_HOURS * 0.012, 0.015),
    "kvarh": Plausible(0, 1e12, _RUN_HOURS * 3, 3),
    "kVAh": Plausible(0, 1e12, _RUN_HOURS * 16, 16),
    None: Plausible(0, 1e9, 100, 1),
}
_STARTS = Plausible(0, 1e9, 420, 0.5)  # a start every two hours
_ANGLES = {"a": 0.0, "ua": 0.0, "b": 120.0, "ub": 120.0, "c": 240.0, "uc": 240.0}
_ENERGY_PER_POWER = {"kWh": {"kW": 1.0, "W": 0.001}, "Wh": {"kW": 1000.0, "W": 1.0}}


def words(key: str) -> frozenset[str]:
    return frozenset(key.lower().split("_"))


def plausible(point: Point) -> Plausible | None:
    """The table's entry for ``point``, with its mapping's ``simulate:`` hint applied."""
    found = _from_table(point)
    hint = point.entity.simulate
    if hint is None or point.entity.enum is not None:  # an enum's hint is its state
        return found
    base = found or Plausible(float("-inf"), float("inf"), 0.0)
    low = hint.min if hint.min is not None else base.low
    high = hint.max if hint.max is not None else base.high
    typical = hint.typical if hint.typical is not None else min(max(base.typical, low), high)
    if hint.typical is None and found is None:
        typical = (low + high) / 2 if hint.min is not None and hint.max is not None else low
    per_hour = hint.per_hour if hint.per_hour is not None else base.per_hour
    return replace(base, low=low, high=high, typical=typical, per_hour=per_hour)


def _from_table(point: Point) -> Plausible | None:
    """Readings only (a state class): a setting or a rating keeps its own value."""
    entity = point.entity
    unit, key = entity.unit, words(point.key)
    if entity.ha.state_class is None:
        return None
    if entity.ha.state_class in COUNTER_CLASSES:
        return _STARTS if "start" in key or "starts" in key else _COUNTED.get(unit)
    if entity.ha.device_class == "power_factor":
        bound = 100.0 if unit == "%" else 1.0
        return Plausible(0.8 * bound, 0.95 * bound, 0.85 * bound)
    if unit == "°":
        angle = next((a for word, a in _ANGLES.items() if word in key), None)
        return None if angle is None else Plausible(max(angle - 2, 0), angle + 2, angle)
    if unit == "V":
        return next((p for marks, p in _VOLTAGES if key & marks), _MEASURED["V"])
    return _MEASURED.get(unit or "")


def energy_source(point: Point, points: AnyMapping[str, Point]) -> tuple[Point, float] | None:
    """An energy counter's power: the device's total power measurement and the factor from
    its unit to the counter's rise per hour (kW -> kWh: 1); None without one."""
    factors = _ENERGY_PER_POWER.get(point.entity.unit or "", {})
    powers = [
        other
        for other in points.values()
        if other.entity.ha.device_class == "power"
        and other.entity.unit in factors
        and other.entity.ha.state_class == "measurement"
        and other.sign is None
    ]
    phases = {"a", "b", "c", "l1", "l2", "l3"}
    total = [p for p in powers if not words(p.key) & phases] or powers
    if not total:
        return None
    source = total[0]
    return source, factors[source.entity.unit or ""]
