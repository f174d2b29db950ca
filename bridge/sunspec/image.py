"""A SunSpec device's register image, built from a device image by pysunspec2's encoders.

A device image is the JSON pysunspec2 reads and writes (its tests' ``device_1547.json``,
``get_json()`` of a scanned device): ``{"name": ..., "models": [{"ID": 1, "L": 66, "Mn":
..., "module": [{...}, ...]}, ...]}``, point values raw (before scale factors), a missing
or null value unimplemented. ``build_image`` lays the models one after the other behind
the ``SunS`` marker at ``base`` and ends the chain with 0xFFFF 0; each model's registers
are pysunspec2's own ``get_mb()`` (sunspec2/file/client.py ``FileClientModel``), so the
simulator serves exactly what pysunspec2 would write, and a test can read it back with
pysunspec2's Modbus client as the reference.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sunspec2.device import ModelError
from sunspec2.file.client import FileClientModel

from bridge.sunspec.models import ModelDefinitionError, load_model
from bridge.sunspec.walk import END, MARKER

_SPACE = 0x10000


class DeviceImageError(ValueError):
    """A device image that cannot be laid out: its message names the model."""


@dataclass(frozen=True, slots=True)
class DeviceImage:
    """Holding registers from ``base``: the marker, every model, the end marker."""

    base: int
    words: tuple[int, ...]
    name: str = ""

    @property
    def registers(self) -> dict[int, int]:
        """Address -> word, for every register the image holds."""
        return {self.base + i: w for i, w in enumerate(self.words)}


def build_image(device: Mapping[str, Any], base: int = 40000, name: str = "") -> DeviceImage:
    """The register image of ``device`` (pysunspec2's device JSON) with its marker at
    ``base``; DeviceImageError for a model pysunspec2 cannot encode or an image that does
    not fit below register 65536."""
    models = device.get("models")
    if not isinstance(models, list) or not models:
        raise DeviceImageError(f"device image {name!r}: no models list")
    words = list(MARKER)
    for index, data in enumerate(models):
        if not isinstance(data, dict) or not isinstance(data.get("ID"), int):
            raise DeviceImageError(f"device image {name!r}: model {index + 1} has no ID")
        if data["ID"] == END:
            break
        words += _model_words(data, f"device image {name!r}, model {data['ID']}")
    words += [END, 0]
    if base < 0 or base + len(words) > _SPACE:
        raise DeviceImageError(f"device image {name!r}: {len(words)} registers from {base}")
    return DeviceImage(base, tuple(words), name or str(device.get("name") or ""))


def load_image(path: Path, base: int = 40000) -> DeviceImage:
    """``build_image`` of a JSON file (DeviceImageError names the file)."""
    try:
        device = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise DeviceImageError(f"{path}: {e}") from e
    if not isinstance(device, dict):
        raise DeviceImageError(f"{path}: not a device image (an object with models)")
    return build_image(device, base, path.name)


def _model_words(data: dict[str, Any], where: str) -> list[int]:
    try:
        load_model(data["ID"])
    except ModelDefinitionError as e:
        raise DeviceImageError(f"{where}: {e}") from e
    try:
        model = FileClientModel(model_id=data["ID"], model_len=data.get("L"), data=data)
        raw: bytes = model.get_mb()
    except (ModelError, ValueError, TypeError, KeyError, struct.error) as e:
        raise DeviceImageError(f"{where}: {e}") from e
    if model.error_info:
        raise DeviceImageError(f"{where}: {model.error_info.strip()}")
    return [int.from_bytes(raw[i : i + 2], "big") for i in range(0, len(raw), 2)]
