"""Which configured devices a raw request to one unit of a bus may reach, and so whose
guards apply to it. Pure.

A raw request (``bridge/request/device/read|write``) names a unit, but the unit id does
not always pick one device:

- On a **serial line** a unit is the device configured at it (1..247; an unconfigured
  unit reaches no device the config knows). Unit 0 is broadcast: every device executes
  it (management requests never send it).
- On a **TCP bus** (``tcp`` and ``rtu-over-tcp``: a gateway, or a device that ignores the
  unit id) unit 0, unit 255 and any unit no device is configured at may be answered by
  any device on the bus; a unit a device is configured at is that device.

The guards of every device that may answer apply: a raw write touching a dangerous
register of one of them needs that device's ``allow_dangerous_writes``; a raw read of a
secret or write-only one needs ``bridge.allow_raw_writes``. And on a TCP bus a raw write
to a unit no device is configured at (0 and 255 included) is refused unless the bus's
``raw_units`` names it: what answers there is not known. Raw reads of such units stay
allowed (scans and commissioning need them), with every device's secret guard.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass

from bridge.core.guard import Guard
from bridge.core.management_request import RequestError
from bridge.core.request import Read, Write

ALIASES = frozenset({0, 255})  # units any device behind a TCP bus may answer as


@dataclass(frozen=True, slots=True)
class Neighbour:
    """A device configured on the bus: its id, its unit, its guard and its config's
    ``allow_dangerous_writes``."""

    device: str
    unit: int
    guard: Guard
    allow_dangerous_writes: bool = False


@dataclass(frozen=True, slots=True)
class Reach:
    """The configured devices a request to ``unit`` on bus ``bus`` may reach."""

    bus: str
    unit: int
    tcp: bool
    devices: tuple[Neighbour, ...]
    configured: bool  # a device is configured at ``unit``

    @property
    def indirect(self) -> bool:
        """The unit may reach a device configured at another unit."""
        return any(d.unit != self.unit for d in self.devices)


def reach_of(bus: str, unit: int, devices: Iterable[Neighbour], *, tcp: bool) -> Reach:
    """Who may answer ``unit`` on a bus with ``devices`` configured (see the module)."""
    everyone = tuple(devices)
    own = tuple(d for d in everyone if d.unit == unit)
    if unit == 0 or (tcp and (unit in ALIASES or not own)):
        return Reach(bus, unit, tcp, everyone, bool(own))
    return Reach(bus, unit, tcp, own, bool(own))


def check_raw_write(reach: Reach, write: Write, raw_units: Collection[int]) -> None:
    """RequestError saying why and what to configure, if ``write`` may not go to the
    unit: an unconfigured TCP unit not in ``raw_units``, or a guarded register of a
    device that may answer it and does not allow dangerous writes."""
    reasons = []
    if reach.tcp and not reach.configured and reach.unit not in raw_units:
        reasons.append(
            f"unit {reach.unit}: no device is configured at it on TCP bus {reach.bus}, where "
            "a gateway or a device that ignores the unit id may answer it"
            + (f" ({_names(reach.devices)})" if reach.devices else "")
            + f"; to write to it raw, add raw_units: [{reach.unit}] to bus {reach.bus}"
        )
    guarded = [
        (d, addresses)
        for d in reach.devices
        if not d.allow_dangerous_writes
        and (addresses := d.guard.dangerous_in(write.table, write.address, write.values))
    ]
    if guarded:
        reasons.append(
            _via(reach)
            + "; ".join(f"{d.device}: addresses {_listed(a)}" for d, a in guarded)
            + " are guarded (dangerous); set allow_dangerous_writes: true for "
            + _devices([d for d, _ in guarded])
            + " to permit it"
        )
    if reasons:
        raise RequestError("; ".join(reasons))


def check_raw_read(reach: Reach, read: Read, *, secrets_allowed: bool) -> None:
    """RequestError if ``read`` would return secret or write-only cells of a device that
    may answer the unit, unless ``secrets_allowed`` (``bridge.allow_raw_writes``)."""
    if secrets_allowed:
        return
    hidden = [
        (d, addresses)
        for d in reach.devices
        if (addresses := d.guard.hidden_in(read.table, read.address, read.count))
    ]
    if hidden:
        raise RequestError(
            _via(reach)
            + "; ".join(f"{d.device}: addresses {_listed(a)}" for d, a in hidden)
            + " hold secret or write-only values; raw reads of them need "
            "bridge.allow_raw_writes: true"
        )


def _via(reach: Reach) -> str:
    """Why devices configured at other units are named, when they are."""
    if not reach.indirect:
        return ""
    why = (
        "on a TCP bus a gateway, or a device that ignores the unit id, answers it"
        if reach.tcp
        else "it is broadcast, every device on the line executes it"
    )
    return f"unit {reach.unit} on bus {reach.bus} may reach {_names(reach.devices)} ({why}): "


def _devices(devices: list[Neighbour]) -> str:
    return ("device " if len(devices) == 1 else "devices ") + _names(devices)


def _names(devices: Iterable[Neighbour]) -> str:
    return ", ".join(d.device for d in devices)


def _listed(addresses: list[int]) -> str:
    shown = ", ".join(str(a) for a in addresses[:8])
    return shown + (f" and {len(addresses) - 8} more" if len(addresses) > 8 else "")
