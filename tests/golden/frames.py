"""Helpers for golden-frame tests: build requests from a mapping, decode documented replies."""

from __future__ import annotations

from bridge.core.codec import Image, Value, decode
from bridge.core.mapping import Mapping, Point, builtin_mapping_path, load_mapping
from bridge.core.request import Read
from bridge.modbus.frame import FramerName, build_frame, parse_frame, response_values


def hexbytes(text: str) -> bytes:
    """``"01 03 00 97"`` -> bytes."""
    return bytes.fromhex(text)


def shipped(name: str) -> Mapping:
    return load_mapping(builtin_mapping_path(name))


def read_of(points: dict[str, Point], *keys: str) -> Read:
    """The one read covering the given points (they must share a table)."""
    chosen = [points[key] for key in keys]
    tables = {p.table for p in chosen}
    assert len(tables) == 1, f"points span several tables: {tables}"
    start = min(p.address for p in chosen)
    end = max(p.address + p.count for p in chosen)
    return Read(chosen[0].table, start, end - start)


def request_frame(read: Read, unit: int = 1, framer: FramerName = "rtu") -> bytes:
    return build_frame(read, unit, framer)


def image_from(read: Read, response: bytes, framer: FramerName = "rtu") -> dict:
    """Register image from a documented response frame to ``read``."""
    values = response_values(parse_frame(response, framer), read)
    return {(read.table, address): value for address, value in zip(read.span, values, strict=True)}


def decoded(points: dict[str, Point], key: str, image: Image) -> Value:
    return decode(points[key], image)
