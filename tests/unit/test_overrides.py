"""Devices of one model with the same protocol overrides share one overridden mapping, as
devices without overrides share the mapping itself: what it works out once (points, guard,
wire limits: the Nastec's reserved registers) is not worked out again for every device
(247 copies held a start's event loop for seconds, issue 27)."""

from __future__ import annotations

from bridge.config import DeviceConfig
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.core.planner import limits_for
from bridge.modbus.poller import _with_overrides


def device(unit: int, **protocol: object) -> DeviceConfig:
    return DeviceConfig.model_validate(
        {
            "id": f"d{unit}",
            "bus": "b",
            "unit": unit,
            "mapping": "nastec_vasco",
            "protocol": protocol,
        }
    )


def test_same_overrides_share_one_mapping_and_its_limits() -> None:
    mapping = load_mapping(builtin_mapping_path("nastec_vasco"))
    first = _with_overrides(mapping, device(1, min_request_interval=0.0))
    second = _with_overrides(mapping, device(2, min_request_interval=0.0))
    assert first is second
    assert first is not mapping and first.protocol.min_request_interval == 0.0
    assert limits_for(first).defined is limits_for(second).defined  # worked out once


def test_other_overrides_get_their_own_and_none_gets_the_mapping() -> None:
    mapping = load_mapping(builtin_mapping_path("nastec_vasco"))
    one = _with_overrides(mapping, device(1, max_read_registers=4))
    other = _with_overrides(mapping, device(2, max_read_registers=8))
    assert one is not other
    assert (one.protocol.max_read_registers, other.protocol.max_read_registers) == (4, 8)
    assert _with_overrides(mapping, device(3)) is mapping
