"""The mapping built from a walked SunSpec device (bridge/sunspec/mapping.py).

Every bundled model definition yields a mapping that ``Mapping`` validates; every entity
of the devices of tests/sunspec_devices.py, decoded by the bridge's codec from the image's
registers, equals what pysunspec2 computes from the same registers (its model objects,
scale factors applied); every point the image leaves unimplemented reads None.
"""

from __future__ import annotations

import asyncio
import math
from typing import Any

import pytest
from sunspec2.file.client import FileClientModel

from bridge.core import codec
from bridge.core.entity import Table
from bridge.core.mapping import Mapping
from bridge.sunspec.image import DeviceImage, build_image
from bridge.sunspec.mapping import BuiltMapping, Source, build_mapping
from bridge.sunspec.models import GroupDef, load_model, model_ids
from bridge.sunspec.walk import Chain, walk
from tests.sunspec_devices import built_model, common, every_image

_LEFT_OUT = ("padding", "an EUI-48", "an IPv6", "its scale factor", "150 registers")


def walked(image: DeviceImage) -> Chain:
    registers = image.registers

    async def read(address: int, count: int) -> list[int]:
        return [registers[a] for a in range(address, address + count)]

    return asyncio.run(walk(read))


def one_model_device(model_id: int) -> dict[str, Any]:
    data = _addresses_as_text(load_model(model_id).group, built_model(model_id))
    return {"models": [common("One", "SN-1"), data, {"ID": 65535, "L": 0}]}


def _addresses_as_text(group: GroupDef, data: Any) -> Any:
    """built_model gives an EUI-48 or IPv6 address a number; pysunspec2 encodes text."""
    if isinstance(data, list):
        return [_addresses_as_text(group, d) for d in data]
    for point in group.points:
        if point.type in _TEXT_ADDRESSES and point.name in data:
            data[point.name] = _TEXT_ADDRESSES[point.type]
    for child in group.groups:
        if child.name in data:
            data[child.name] = _addresses_as_text(child, data[child.name])
    return data


_TEXT_ADDRESSES = {"eui48": "00:11:22:33:44:55", "ipv6addr": "FE800000:00000000:00000000:00000001"}
MODELS = [i for i in model_ids() if i != 1]


@pytest.mark.parametrize("model_id", MODELS)
def test_every_bundled_model_builds_a_mapping_that_validates(model_id: int) -> None:
    image = build_image(one_model_device(model_id))
    built = build_mapping(walked(image), image.registers)
    mapping = built.mapping()
    assert isinstance(mapping, Mapping)
    assert not [s for s in built.skipped if not s.point], built.skipped  # no model left out
    assert all(s.reason.startswith(_LEFT_OUT) for s in built.skipped), built.skipped
    mine = [k for k, s in built.sources.items() if s.model_id == model_id]
    assert mine, f"model {model_id}: no entity"


def test_a_model_whose_layout_needs_a_count_is_left_out_without_the_registers() -> None:
    image = build_image(one_model_device(705))
    chain = walked(image)
    built = build_mapping(chain)
    assert [(s.model, s.point) for s in built.skipped if not s.point] == [(705, "")]
    assert "NCrv" in next(s.reason for s in built.skipped if not s.point)
    assert all(s.model_id == 1 for s in built.sources.values())
    with_registers = build_mapping(chain, image.registers)
    assert any(s.model_id == 705 for s in with_registers.sources.values())


# --- decode: the codec against pysunspec2 --------------------------------------------


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


def decoded(built: BuiltMapping, image: DeviceImage) -> dict[str, Any]:
    words = {(Table.HOLDING, a): w for a, w in image.registers.items()}
    return {key: codec.decode(p, words) for key, p in built.mapping().points().items()}


def same(value: Any, wanted: Any) -> bool:
    """Equal: None only as None, a boolean only as a boolean, a float within rounding."""
    if wanted is None or value is None or isinstance(wanted, bool) or isinstance(value, bool):
        return value is wanted
    if isinstance(wanted, float) and isinstance(value, int | float):
        return math.isclose(value, wanted, rel_tol=1e-6, abs_tol=1e-9)
    return bool(value == wanted)


IMAGES = every_image()


@pytest.mark.parametrize("name", sorted(IMAGES))
def test_every_point_decodes_to_pysunspec2s_value(name: str) -> None:
    device = IMAGES[name]
    image = build_image(device)
    chain = walked(image)
    built = build_mapping(chain, image.registers)
    models = reference_models(image, chain, device)
    values = decoded(built, image)
    entities = built.document["entities"]
    scales = {key: reference_point(models, s) for key, s in built.sources.items() if s.bit is None}
    wrong = []
    for key, source in built.sources.items():
        want = expected(reference_point(models, source), source, entities[key], scales)
        if not same(values[key], want):
            wrong.append(f"{key}: bridge {values[key]!r}, pysunspec2 {want!r}")
    assert wrong == []
    assert any(v is None for v in values.values())  # some points unimplemented
    assert sum(v is not None for v in values.values()) > len(values) // 2


@pytest.mark.parametrize("model_id", MODELS)
def test_every_model_decodes_to_pysunspec2s_values(model_id: int) -> None:
    device = one_model_device(model_id)
    image = build_image(device)
    chain = walked(image)
    built = build_mapping(chain, image.registers)
    models = reference_models(image, chain, device)
    values = decoded(built, image)
    entities = built.document["entities"]
    scales = {k: reference_point(models, s) for k, s in built.sources.items() if s.bit is None}
    wrong = [
        f"{key}: bridge {values[key]!r}, pysunspec2 {want!r}"
        for key, source in built.sources.items()
        if not same(
            values[key],
            want := expected(reference_point(models, source), source, entities[key], scales),
        )
    ]
    assert wrong == []
