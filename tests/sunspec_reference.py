"""pysunspec2 as the reference reader of a SunSpec device image, for the tests of the
mapping builder (tests/unit/test_sunspec_mapping.py, tests/integration/
test_sunspec_bridge.py): what the bridge must publish for each entity a built mapping
has, computed by pysunspec2's model objects from the image's registers (scale factors
applied by pysunspec2, unimplemented values None)."""

from __future__ import annotations

import asyncio
import math
from typing import Any

from sunspec2.file.client import FileClientModel

from bridge.core import codec
from bridge.errors import DeviceExceptionError
from bridge.sunspec.image import DeviceImage
from bridge.sunspec.mapping import BuiltMapping, Source
from bridge.sunspec.walk import Chain, walk


def walked(image: DeviceImage) -> Chain:
    """The walk of an image's registers, in memory."""
    registers = image.registers

    async def read(address: int, count: int) -> list[int]:
        if not all(a in registers for a in range(address, address + count)):
            raise DeviceExceptionError(2, "illegal data address", "fail")  # as a device does
        return [registers[a] for a in range(address, address + count)]

    return asyncio.run(walk(read))


def reference_models(image: DeviceImage, chain: Chain, device: dict[str, Any]) -> list[Any]:
    """pysunspec2's model objects, each set from the image's registers."""
    given = [m for m in device["models"] if m["ID"] != 65535]
    found = []
    for model, data in zip(chain.models, given, strict=True):
        ref = FileClientModel(model_id=model.id, model_len=model.length, data=data)
        span = range(model.address, model.end)
        ref.set_mb(b"".join(image.registers[a].to_bytes(2, "big") for a in span))
        assert not ref.error_info, ref.error_info
        found.append(ref)
    return found


def reference_point(models: list[Any], source: Source) -> Any:
    group = models[source.model]
    for name, index in source.path:
        group = group.groups[name][index - 1] if index else group.groups[name]
    return group.points[source.point]


def expected(point: Any, source: Source, entity: dict[str, Any], scales: dict[str, Any]) -> Any:
    """What the bridge must publish for pysunspec2's ``point``."""
    raw = point.value
    if raw is None:
        return None
    if source.bit is not None:
        return bool(raw >> source.bit & 1)
    if "enum" in entity:
        return entity["enum"].get(raw, codec.unknown_code(raw))
    if isinstance(raw, str):
        return raw.rstrip(" ")
    if "scale_by" in entity and scales[entity["scale_by"]].value is None:
        return None  # pysunspec2 leaves the raw value unscaled; the bridge reads unknown
    return point.cvalue


def same(value: Any, wanted: Any) -> bool:
    """Equal: None only as None, a boolean only as a boolean, a float within rounding."""
    if wanted is None or value is None or isinstance(wanted, bool) or isinstance(value, bool):
        return value is wanted
    if isinstance(wanted, float) and isinstance(value, int | float):
        return math.isclose(value, wanted, rel_tol=1e-6, abs_tol=1e-9)
    return bool(value == wanted)


def expected_values(built: BuiltMapping, models: list[Any]) -> dict[str, Any]:
    """What the bridge must publish for every entity of ``built``, by pysunspec2."""
    entities = built.document["entities"]
    scales = {k: reference_point(models, s) for k, s in built.sources.items() if s.bit is None}
    return {
        key: expected(reference_point(models, source), source, entities[key], scales)
        for key, source in built.sources.items()
    }


def differences(values: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    """Every key whose value is not pysunspec2's."""
    return [
        f"{key}: bridge {values.get(key)!r}, pysunspec2 {want!r}"
        for key, want in wanted.items()
        if not same(values.get(key), want)
    ]
