"""SunSpec device images for the tests: pysunspec2's own test devices, and devices built
from the model definitions (every point given a value its type can hold, some optional
ones left unimplemented), in pysunspec2's device JSON."""

from __future__ import annotations

import json
import random
from importlib import resources
from typing import Any

from sunspec2 import mb as ss_mb
from sunspec2.file.client import FileClientModel

from bridge.sunspec.models import GroupDef, PointDef, load_model

PYSUNSPEC2_IMAGES = ("device_1547.json", "inverter_123.json")


def pysunspec2_image(name: str) -> dict[str, Any]:
    """One of the device images of pysunspec2's own tests."""
    source = resources.files("sunspec2.tests.test_data").joinpath(name)
    return dict(json.loads(source.read_text(encoding="utf-8")))


def common(model: str, serial: str) -> dict[str, Any]:
    return {
        "ID": 1,
        "Mn": "Bridge Test Works",
        "Md": model,
        "Opt": None,
        "Vr": "2.4.1",
        "SN": serial,
        "DA": 3,
    }


def built_model(model_id: int, instances: int = 2, seed: int = 0) -> dict[str, Any]:
    """A model with every point of its definition given a value (repeating groups
    ``instances`` times), some optional points left out (unimplemented)."""
    model = load_model(model_id)
    rng = random.Random(model_id * 1000 + seed)
    counts = _counts(model.group, instances)
    data = _group_values(model.group, counts, rng, instances)
    data["ID"] = model_id
    return data


def built_devices() -> dict[str, dict[str, Any]]:
    """The devices the issue asks for besides pysunspec2's: an inverter with four MPPTs
    (103 + 160), a meter (203), a battery (124 storage with 802)."""
    return {
        "inverter_mppt": {
            "name": "inverter_mppt",
            "models": [
                common("Three Phase 10k", "INV-0042"),
                built_model(103),
                built_model(120),
                built_model(160, instances=4),
                {"ID": 65535, "L": 0},
            ],
        },
        "meter": {
            "name": "meter",
            "models": [common("Meter 3P", "MTR-7"), built_model(203), {"ID": 65535, "L": 0}],
        },
        "battery": {
            "name": "battery",
            "models": [
                common("Battery 10", "BAT-2026"),
                built_model(124),
                built_model(802),
                {"ID": 65535, "L": 0},
            ],
        },
    }


def every_image() -> dict[str, dict[str, Any]]:
    images = {name.removesuffix(".json"): pysunspec2_image(name) for name in PYSUNSPEC2_IMAGES}
    return images | built_devices()


def reference_values(device: Any) -> list[dict[str, Any]]:
    """pysunspec2's raw values of every model of a scanned device."""
    return [m.get_dict() for m in device.model_list]


def expected_values(image: dict[str, Any]) -> list[dict[str, Any]]:
    """The image's models as pysunspec2 would read them back: what the file client
    holds after encoding (unimplemented points None)."""
    found = []
    for data in image["models"]:
        if data["ID"] == ss_mb.SUNS_END_MODEL_ID:
            break
        model = FileClientModel(model_id=data["ID"], model_len=data.get("L"), data=data)
        model.set_mb(model.get_mb())  # through registers: what a reader sees
        found.append(model.get_dict())
    return found


def mismatches(given: Any, read: Any, path: str = "") -> list[str]:
    """Where a value the image gives differs from what was read back: every non-null
    value of a point the definition has (pysunspec2's own test images carry a few keys of
    older model revisions, such as 701's ``VL3N``; no definition places them)."""
    if isinstance(given, dict) and isinstance(read, dict):
        return [
            found
            for key, value in given.items()
            if key in read
            for found in mismatches(value, read[key], f"{path}/{key}")
        ]
    if isinstance(given, list) and isinstance(read, list) and len(given) == len(read):
        return [
            m
            for i, (g, r) in enumerate(zip(given, read, strict=True))
            for m in mismatches(g, r, f"{path}/{i}")
        ]
    if given is None or given == read:
        return []
    return [f"{path}: image {given!r}, read {read!r}"]


def comparable(values: dict[str, Any]) -> dict[str, Any]:
    """A model's values without pysunspec2's bookkeeping (its ids, errors)."""
    return {k: v for k, v in values.items() if k not in {"mid", "error", "model_id"}}


def _counts(group: GroupDef, instances: int) -> dict[str, int]:
    names = {group.count: instances} if isinstance(group.count, str) else {}
    for child in group.groups:
        names |= _counts(child, instances)
    return names


def _group_values(
    group: GroupDef, counts: dict[str, int], rng: random.Random, instances: int
) -> dict[str, Any]:
    data: dict[str, Any] = {}
    for point in group.points:
        if point.value is not None or (point.name == "L" and point.offset == 1):
            continue  # the model's ID and L: pysunspec2 writes them
        if point.name in counts:
            data[point.name] = counts[point.name]
        elif point.type == "count":  # model 160's N: the modules its length holds
            data[point.name] = instances
        elif point.mandatory or point.type in {"sunssf", "pad"} or rng.random() > 0.2:
            data[point.name] = _value(point, rng)
    for child in group.groups:
        if child.count is None:
            data[child.name] = _group_values(child, counts, rng, instances)
            continue
        number = counts.get(child.count, 0) if isinstance(child.count, str) else child.count
        number = number or instances  # 0: counted by the model's length
        data[child.name] = [_group_values(child, counts, rng, instances) for _ in range(number)]
    return data


def _value(point: PointDef, rng: random.Random) -> Any:
    kind = point.type
    if point.symbols and kind.startswith("enum"):
        return rng.choice(point.symbols).value
    if point.symbols and kind.startswith("bitfield"):
        return sum(1 << s.value for s in rng.sample(point.symbols, min(2, len(point.symbols))))
    if kind == "sunssf":
        return rng.randint(-3, 2)
    if kind == "pad":
        return 0x8000
    if kind == "string":
        return "".join(rng.choice("ABCDEFGH0123456789") for _ in range(min(point.size * 2, 12)))
    if kind in {"int16", "int32", "int64"}:
        return rng.randint(-2000, 30000)
    if kind in {"acc32", "acc64", "uint32", "uint64"}:
        return rng.randint(1, 4_000_000)
    if kind in {"float32", "float64"}:
        return rng.randint(-4000, 4000) / 4
    if kind == "ipaddr":
        return rng.randint(1, 0xFFFFFFFE)
    return rng.randint(1, 60000)  # uint16, acc16, count, enum/bitfield without symbols
