"""The walk of a SunSpec device's model chain: pure, bounded, the caller's read does the I/O.

``await walk(read)`` looks for the ``SunS`` marker (0x5375 0x6E53) at each base in turn
(40000, 50000, 0 unless the device's base is configured), then follows the chain: each
model's ID and length L, the next ID at ``address + 2 + L``, until the end marker 0xFFFF.
``read(address, count)`` reads holding registers and raises ``DeviceExceptionError`` when
the unit refuses (then the next base is tried) and any other error when it does not
answer (then the walk stops: a silent unit costs one timeout, not three).

Requests: one per base tried (the marker, the first model's ID and L in one read), then
one per model (the next ID and L; the common model's body is read with the next ID and L
when they fit the read limit), so at most ``len(bases) + max_models + 2 +
ceil(66 / read_limit)`` (``request_bound``; the 2: an end marker whose L is refused, read
again alone, and the common model's body). Of a common model longer than its definition
only the definition's 66 registers are read.

``await read_chain(read, chain)`` then reads every register of the walked models (what
the mapping builder needs of a device), one request per model where the read limit allows.

The walk refuses what a device cannot mean: a chain that runs past register 65535
(addresses only grow, so that is also the only way a chain can loop), more than
``max_models`` models or ``max_registers`` registers, a model ID of 0, an answer shorter
than asked.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass

from bridge.errors import DeviceExceptionError, NotSunSpecError, SunSpecChainError
from bridge.sunspec.models import HEADER, load_model

Read = Callable[[int, int], Awaitable[Sequence[int]]]
BASES = (40000, 50000, 0)  # where devices put the marker, in the order tried
MARKER = (0x5375, 0x6E53)  # "SunS"
END = 0xFFFF  # the ID that ends the chain
COMMON = 1  # the common model: manufacturer, model, serial number
_SPACE = 0x10000  # holding registers 0..65535
_COMMON_LENGTH = 66  # model 1's L by its definition (tests check it against models.py)
_STRINGS = frozenset({"Mn", "Md", "Opt", "Vr", "SN"})  # the common model's strings


@dataclass(frozen=True, slots=True)
class WalkLimits:
    """The bounds of one walk: registers per read, models and registers in the chain."""

    read_limit: int = 125
    max_models: int = 100
    max_registers: int = 10_000


@dataclass(frozen=True, slots=True)
class ChainModel:
    """One model of the chain: ``address`` of its ID register, ``length`` its L (the
    registers after ID and L)."""

    id: int
    address: int
    length: int

    @property
    def end(self) -> int:
        """The address after the model: the next model's ID register."""
        return self.address + HEADER + self.length


@dataclass(frozen=True, slots=True)
class Common:
    """The common model (1), decoded; None where the device leaves a point unimplemented
    (an all-NUL string, DA 0xFFFF)."""

    manufacturer: str | None
    model: str | None
    options: str | None
    version: str | None
    serial_number: str | None
    device_address: int | None


@dataclass(frozen=True, slots=True)
class Chain:
    """A walked device: the marker's ``base``, its models in order (the end marker left
    out), the first common model decoded (None if it has none) and the ``requests`` the
    walk made."""

    base: int
    models: tuple[ChainModel, ...]
    common: Common | None
    requests: int

    @property
    def model_ids(self) -> tuple[int, ...]:
        return tuple(m.id for m in self.models)


def request_bound(bases: Sequence[int] = BASES, limits: WalkLimits | None = None) -> int:
    """The most requests a walk makes, whatever the device answers."""
    limits = limits or WalkLimits()
    return len(bases) + limits.max_models + 2 + math.ceil(_COMMON_LENGTH / limits.read_limit)


async def walk(read: Read, bases: Sequence[int] = BASES, limits: WalkLimits | None = None) -> Chain:
    """Find the marker at the first of ``bases`` that has it and walk the chain from
    there. NotSunSpecError: no base has it; SunSpecChainError: the chain is malformed or
    beyond ``limits``; a read's own error when the unit does not answer."""
    limits = limits or WalkLimits()
    if limits.read_limit < HEADER + 2:
        raise ValueError(f"read_limit {limits.read_limit}: a walk needs at least 4")
    counted = _Counted(read, limits.read_limit)
    for base in bases:
        if not 0 <= base <= _SPACE - 4:
            raise ValueError(f"base {base}: the marker and a model header need 4 registers")
        try:
            head = await counted.span(base, 4)
        except DeviceExceptionError:
            continue
        if tuple(head[:2]) == MARKER:
            try:
                models, common = await _follow(counted, base + 2, (head[2], head[3]), limits)
            except DeviceExceptionError as e:
                refused = SunSpecChainError(f"the chain from {base}: a read was refused ({e})")
                refused.base = base
                raise refused from e
            except SunSpecChainError as e:
                e.base = base
                raise
            return Chain(base, models, common, counted.requests)
    tried = ", ".join(str(b) for b in bases)
    raise NotSunSpecError(f"no SunSpec marker at {tried} ({counted.requests} requests)")


async def read_chain(read: Read, chain: Chain, read_limit: int = 125) -> dict[int, int]:
    """Every register of the chain's models (ID, L and body), address -> word, in reads of
    at most ``read_limit``: what ``bridge.sunspec.mapping.build_mapping`` needs of a
    device (the points that count a model's groups, a module's IDStr). Requests:
    ``ceil((L + 2) / read_limit)`` per model; a short answer is refused
    (SunSpecChainError), a refused read raises the read's own error."""
    if read_limit < 1:
        raise ValueError(f"read_limit {read_limit}: at least 1")
    counted = _Counted(read, read_limit)
    words: dict[int, int] = {}
    for model in chain.models:
        span = await counted.span(model.address, model.end - model.address)
        words.update(zip(range(model.address, model.end), span, strict=True))
    return words


class _Counted:
    """The caller's read, counted and split at the read limit; a short answer refused."""

    def __init__(self, read: Read, limit: int) -> None:
        self.read = read
        self.limit = limit
        self.requests = 0

    async def span(self, address: int, count: int) -> list[int]:
        words: list[int] = []
        while len(words) < count:
            at, size = address + len(words), min(self.limit, count - len(words))
            self.requests += 1
            answer = list(await self.read(at, size))
            if len(answer) != size:
                raise SunSpecChainError(
                    f"read of {size} registers at {at} answered {len(answer)}: not SunSpec"
                )
            words += answer
        return words


async def _follow(
    counted: _Counted, address: int, header: tuple[int, int], limits: WalkLimits
) -> tuple[tuple[ChainModel, ...], Common | None]:
    """The models from ``address`` (whose ID and L are ``header``) to the end marker."""
    models: list[ChainModel] = []
    common: Common | None = None
    start = address
    while header[0] != END:
        model = _checked(ChainModel(header[0], address, header[1]), start, len(models), limits)
        models.append(model)
        tail = _SPACE - model.end  # registers left after the model
        if model.id == COMMON and common is None:
            wanted = min(model.length, _COMMON_LENGTH)  # the points the definition has
            with_next = wanted == model.length and wanted + HEADER <= counted.limit
            with_next = with_next and tail >= HEADER
            body = await counted.span(address + HEADER, wanted + (HEADER if with_next else 0))
            common = _common(body[:wanted], wanted)
            if with_next:
                header, address = (body[-2], body[-1]), model.end
                continue
        if tail < HEADER:
            raise SunSpecChainError(f"model {model.id} at {address} ends at 65535: no end marker")
        address = model.end
        header = await _header(counted, address)
    return tuple(models), common


async def _header(counted: _Counted, address: int) -> tuple[int, int]:
    """The ID and L at ``address``; a device that refuses the end marker's L (pysunspec2
    reads the ID alone for every model) is asked for the ID alone."""
    try:
        words = await counted.span(address, HEADER)
    except DeviceExceptionError:
        (model_id,) = await counted.span(address, 1)
        if model_id != END:
            raise
        return END, 0
    return words[0], words[1]


def _checked(model: ChainModel, start: int, found: int, limits: WalkLimits) -> ChainModel:
    where = f"model {model.id} at {model.address}"
    if model.id == 0:
        raise SunSpecChainError(f"model id 0 at {model.address}: the chain has no end marker")
    if found >= limits.max_models:
        raise SunSpecChainError(f"{where}: more than {limits.max_models} models")
    if model.end > _SPACE:
        raise SunSpecChainError(f"{where}, length {model.length}: runs past register 65535")
    if model.end - start > limits.max_registers:
        raise SunSpecChainError(f"{where}: the chain passes {limits.max_registers} registers")
    return model


def _common(words: list[int], length: int) -> Common:
    """Model 1's points, found by the definition's offsets (ID and L not in ``words``)."""
    strings: dict[str, str | None] = {}
    device_address: int | None = None
    for point in load_model(COMMON).group.points:
        at = point.offset - HEADER
        if at < 0 or at + point.size > length:
            continue
        if point.name in _STRINGS:
            strings[point.name] = text(words[at : at + point.size])
        elif point.name == "DA":
            device_address = None if words[at] == END else words[at]
    return Common(
        manufacturer=strings.get("Mn"),
        model=strings.get("Md"),
        options=strings.get("Opt"),
        version=strings.get("Vr"),
        serial_number=strings.get("SN"),
        device_address=device_address,
    )


def text(words: Sequence[int]) -> str | None:
    """A SunSpec string: two bytes per register, high byte first, NULs and spaces around
    stripped; None when it is unimplemented (its first byte NUL) or empty."""
    raw = b"".join(w.to_bytes(2, "big") for w in words)
    if not raw or raw[0] == 0:
        return None
    value = raw.decode("utf-8", errors="replace").strip("\0 ")
    return value or None
