"""``identify``: what answers at a unit, read-only and bounded (bridge/core/identify.py).

    async with open_bus(bus) as submit:
        identity = await identify_unit(submit, 3, library, timeout=0.5, bus_id="rs485")

One unit: scan's probe first (no answer: absent, one timeout spent, None); then the
SunSpec walk (``sunspec_device``: the marker at holding 40000, 50000, 0, the model chain
and the common model, bridge/sunspec/walk.py, within ``WALK``); for a unit without it, each
mapping's fingerprint reads, required ones first (a mapping ruled out gets no more), a
read two mappings share sent once, each within its mapping's function codes and read
limits (the mapping refuses a fingerprint that is not). Reads only: nothing here
builds a write. The answers are scored by ``rank``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from collections.abc import Mapping as AnyMapping

from bridge.core.entity import Table
from bridge.core.fingerprint import matches
from bridge.core.identify import MAX_SILENT, Identity, SunSpecDevice, probes_of, rank
from bridge.core.identify import request_bound as bound_of
from bridge.core.mapping import Mapping
from bridge.core.request import Read, Write
from bridge.errors import (
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    NotSunSpecError,
    SunSpecChainError,
)
from bridge.modbus.commission import Submit, probe
from bridge.sunspec.walk import BASES, WalkLimits, walk
from bridge.sunspec.walk import request_bound as walk_bound

WALK = WalkLimits(max_models=40)  # identify's walk: a device lists 5 to 20 models


class _Counted:
    """A read-only ``Submit`` that counts the requests sent and the ones left unanswered."""

    def __init__(self, submit: Submit) -> None:
        self._submit = submit
        self.requests = 0
        self.silent = 0

    async def __call__(self, unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
        if not isinstance(request, Read):
            raise TypeError("identify never writes")
        self.requests += 1
        try:
            return await self._submit(unit, request, timeout)
        except DeviceTimeoutError:
            self.silent += 1
            raise

    async def read(self, unit: int, request: Read, timeout: float) -> tuple[int, ...] | None:
        """The values, or None for an exception, a garbled answer or no answer."""
        try:
            return await self(unit, request, timeout)
        except (DeviceExceptionError, FrameError, DeviceTimeoutError):
            return None


def request_bound(library: AnyMapping[str, Mapping]) -> int:
    """The most requests ``identify`` sends one unit (scan's probe included)."""
    return bound_of(library, walk_bound(BASES, WALK), len(BASES))


async def sunspec_device(submit: Submit, unit: int, timeout: float) -> SunSpecDevice | None:
    """The SunSpec device at ``unit`` (its chain walked from the first base with the
    marker, within ``WALK``), or None where no base has it. A chain that cannot be walked
    to its end still names the base, with a note."""
    counted = submit if isinstance(submit, _Counted) else _Counted(submit)

    async def read(address: int, count: int) -> tuple[int, ...]:
        return await counted(unit, Read(Table.HOLDING, address, count), timeout)

    try:
        chain = await walk(read, BASES, WALK)
    except NotSunSpecError:
        return None
    except SunSpecChainError as e:
        return SunSpecDevice(e.base, note=str(e)) if e.base is not None else None
    common = chain.common
    if common is None:
        return SunSpecDevice(chain.base, models=chain.model_ids)
    return SunSpecDevice(
        chain.base,
        common.manufacturer,
        common.model,
        common.version,
        common.serial_number,
        chain.model_ids,
    )


async def identify_unit(
    submit: Submit,
    unit: int,
    library: AnyMapping[str, Mapping],
    timeout: float,
    bus_id: str,
    *,
    read_timeout: float | None = None,
) -> Identity | None:
    """What ``unit`` is; None when it does not answer scan's probe within ``timeout``
    (one timeout). The reads after it wait ``read_timeout`` (default ``timeout``)."""
    if await probe(submit, unit, timeout) is None:
        return None
    timeout = read_timeout or timeout
    counted = _Counted(submit)
    try:
        sunspec = await sunspec_device(counted, unit, timeout)
    except (DeviceTimeoutError, FrameError):
        note = "stopped: the SunSpec marker's read went unanswered"
        return Identity(unit, bus_id, None, (), 1 + counted.requests, note)
    if sunspec is not None:
        return Identity(unit, bus_id, sunspec, (), 1 + counted.requests)
    answers = await _fingerprint_answers(counted, unit, library, timeout)
    if answers is None:
        note = f"stopped: {counted.silent} reads went unanswered"
        return Identity(unit, bus_id, None, (), 1 + counted.requests, note)
    found = rank(library, unit, answers)
    return Identity(unit, bus_id, None, found, 1 + counted.requests)


async def _fingerprint_answers(
    counted: _Counted, unit: int, library: AnyMapping[str, Mapping], timeout: float
) -> dict[Read, tuple[int, ...] | None] | None:
    """What the unit answered to each fingerprint read sent; None once it went silent."""
    answers: dict[Read, tuple[int, ...] | None] = {}
    for mapping in library.values():
        for check, read in probes_of(mapping):
            if counted.silent >= MAX_SILENT:
                return None
            if read not in answers:
                answers[read] = await counted.read(unit, read, timeout)
            if check.required and not matches(check, unit, answers[read]):
                break  # ruled out: the rest of its reads would say nothing
    return answers


async def identify(
    submit: Submit,
    units: Iterable[int],
    library: AnyMapping[str, Mapping],
    timeout: float,
    bus_id: str,
    *,
    on_progress: Callable[[int, Identity | None], None] | None = None,
    read_timeout: float | None = None,
) -> list[Identity]:
    """``identify_unit`` for each of ``units`` in turn (one frame in flight)."""
    found = []
    for unit in tuple(units):
        wait = read_timeout
        identity = await identify_unit(submit, unit, library, timeout, bus_id, read_timeout=wait)
        if identity is not None:
            found.append(identity)
        if on_progress is not None:
            on_progress(unit, identity)
    return found
