"""``identify``: what answers at a unit, read-only and bounded (bridge/core/identify.py).

    async with open_bus(bus) as submit:
        identity = await identify_unit(submit, 3, library, timeout=0.5, bus_id="rs485")

One unit: scan's probe first (no answer: absent, one timeout spent, None); then the
SunSpec marker (``sunspec_base``: holding 40000, 50000, 0); for a unit without it, each
mapping's fingerprint reads, required ones first (a mapping ruled out gets no more), a
read two mappings share sent once, each within its mapping's function codes and read
limits (the mapping refuses a fingerprint that is not). Reads only: nothing here
builds a write. The answers are scored by ``rank``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from collections.abc import Mapping as AnyMapping

from bridge.core.fingerprint import matches
from bridge.core.identify import (
    MAX_SILENT,
    SUNSPEC_BASES,
    Identity,
    is_marker,
    marker_read,
    probes_of,
    rank,
)
from bridge.core.mapping import Mapping
from bridge.core.request import Read, Write
from bridge.errors import DeviceExceptionError, DeviceTimeoutError, FrameError
from bridge.modbus.commission import Submit, probe


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


async def sunspec_base(submit: Submit, unit: int, timeout: float) -> int | None:
    """The base (40000, 50000 or 0) whose 2 holding registers read ``SunS``, or None: the
    one place a SunSpec model walk starts from. Stops at the first base found, and after
    ``MAX_SILENT`` unanswered reads."""
    counted = submit if isinstance(submit, _Counted) else _Counted(submit)
    for base in SUNSPEC_BASES:
        if counted.silent >= MAX_SILENT:
            return None
        if is_marker(await counted.read(unit, marker_read(base), timeout)):
            return base
    return None


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
    base = await sunspec_base(counted, unit, timeout)
    if base is not None:
        return Identity(unit, bus_id, base, (), 1 + counted.requests)
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
