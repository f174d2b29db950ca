"""The mapping built from a walked SunSpec device (bridge/sunspec/mapping.py).

Every bundled model definition yields a mapping that ``Mapping`` validates; every entity
of the devices of tests/sunspec_devices.py, decoded by the bridge's codec from the image's
registers, equals what pysunspec2 computes from the same registers (its model objects,
scale factors applied); every point the image leaves unimplemented reads None.
"""

from __future__ import annotations

import asyncio
import json
import random
import tracemalloc
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.core import codec
from bridge.core.discovery import DeviceInfo, Origin, build_discovery
from bridge.core.entity import Table
from bridge.core.mapping import Mapping, parse_mapping
from bridge.core.planner import limits_for, plan_reads
from bridge.core.topics import Topics
from bridge.errors import DeviceExceptionError
from bridge.sunspec.image import DeviceImage, build_image
from bridge.sunspec.mapping import BuiltMapping, build_from_device, build_mapping
from bridge.sunspec.models import GroupDef, ModelDefinitionError, layout, load_model, model_ids
from bridge.sunspec.walk import Chain, ChainModel, WalkLimits, read_chain
from tests.sunspec_devices import built_model, common, every_image
from tests.sunspec_reference import differences, expected_values, reference_models, walked

_LEFT_OUT = (
    "padding",
    "an EUI-48",
    "an IPv6",
    "it and its scale factor",
    "no read",
    "150 registers",
)


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


def decoded(built: BuiltMapping, image: DeviceImage) -> dict[str, Any]:
    """Every entity decoded by the bridge's codec from the image's registers."""
    words = {(Table.HOLDING, a): w for a, w in image.registers.items()}
    return {key: codec.decode(p, words) for key, p in built.mapping().points().items()}


def check_against_pysunspec2(device: dict[str, Any]) -> dict[str, Any]:
    image = build_image(device)
    chain = walked(image)
    built = build_mapping(chain, image.registers)
    values = decoded(built, image)
    assert set(values) == set(built.sources)
    wanted = expected_values(built, reference_models(image, chain, device))
    assert differences(values, wanted) == []
    return values


IMAGES = every_image()


@pytest.mark.parametrize("name", sorted(IMAGES))
def test_every_point_of_the_test_devices_decodes_to_pysunspec2s_value(name: str) -> None:
    values = check_against_pysunspec2(IMAGES[name])
    assert any(v is None for v in values.values())  # some points unimplemented
    assert sum(v is not None for v in values.values()) > len(values) // 2


@pytest.mark.parametrize("model_id", MODELS)
def test_every_point_of_every_model_decodes_to_pysunspec2s_value(model_id: int) -> None:
    check_against_pysunspec2(one_model_device(model_id))


# --- what the entities are ----------------------------------------------------------


def built_device(name: str, *, with_registers: bool = True) -> BuiltMapping:
    image = build_image(IMAGES[name])
    return build_mapping(walked(image), image.registers if with_registers else None)


def test_keys_and_names_follow_model_group_and_point() -> None:
    plain = built_device("inverter_mppt", with_registers=False).document["entities"]
    assert plain["mppt_module_2_dcw"]["name"] == "Module 2 DC power"
    assert plain["inverter_three_phase_w"]["name"] == "Watts"
    named = built_device("inverter_mppt").document["entities"]
    module_id = IMAGES["inverter_mppt"]["models"][3]["module"][1]["IDStr"]
    assert named["mppt_module_2_dcw"]["name"] == f"{module_id} DC power"
    assert len({e["name"] for e in named.values()}) == len(named)  # names unique


def test_a_number_is_scaled_by_its_sunssf_with_its_unit_and_classes() -> None:
    entities = built_device("inverter_mppt").document["entities"]
    watts = entities["inverter_three_phase_w"]
    assert (watts["type"], watts["scale_by"], watts["unit"]) == (
        "s16",
        "inverter_three_phase_w_sf",
        "W",
    )
    assert watts["ha"] == {"device_class": "power", "state_class": "measurement"}
    assert watts["sentinels"] == {0x8000: "not implemented"}
    factor = entities["inverter_three_phase_w_sf"]
    assert (factor["type"], factor["sentinels"], factor["ha"], factor["poll"]) == (
        "s16",
        {0x8000: "not implemented"},
        {"entity_category": "diagnostic"},
        "slow",  # read with every value it scales
    )
    assert "poll" not in watts
    energy = entities["inverter_three_phase_wh"]  # acc32: a counter
    assert (energy["type"], energy["sentinels"], energy["unit"]) == (
        "u32",
        {0: "not implemented"},
        "Wh",
    )
    assert energy["ha"] == {"device_class": "energy", "state_class": "total_increasing"}
    temperature = entities["inverter_three_phase_tmpcab"]
    assert (temperature["unit"], temperature["ha"]["device_class"]) == ("°C", "temperature")


def test_a_fixed_scale_factor_is_a_fixed_scale() -> None:
    image = build_image(one_model_device(304))  # inclinometer: Inclx at 10**-2
    built = build_mapping(walked(image), image.registers)
    assert built.document["entities"]["inclinometer_incl_1_inclx"]["scale"] == 0.01


def test_enums_bitfields_and_the_status() -> None:
    document = built_device("inverter_mppt").document
    entities = document["entities"]
    assert document["status"] == "inverter_three_phase_st"
    state = entities["inverter_three_phase_st"]
    assert state["enum"][4] == "mppt" and state["sentinels"] == {0xFFFF: "not implemented"}
    raw = entities["inverter_three_phase_evt1"]  # bitfield32: the word, diagnostic
    assert (raw["type"], raw["sentinels"]) == ("u32", {0xFFFFFFFF: "not implemented"})
    ground = entities["inverter_three_phase_evt1_ground_fault"]  # bit 0: the low word
    assert (ground["address"], ground["bit"]) == (raw["address"] + 1, 0)
    assert ground["alarm"] is True and ground["ha"] == {"device_class": "problem"}
    assert "inverter_three_phase_evt1_reserved_2" not in entities
    modes = built_device("device_1547").document["entities"]["der_capacity_ctrlmodes_max_w"]
    assert "alarm" not in modes and modes["ha"] == {"entity_category": "diagnostic"}
    symbols = load_model(160).group.point("Evt").symbols
    high = next(s for s in symbols if s.value >= 16 and not s.name.startswith("RESERVED"))
    bit = entities[f"mppt_evt_{high.name.lower()}"]  # bit 16 or more: the high word
    assert (bit["address"], bit["bit"]) == (entities["mppt_evt"]["address"], high.value - 16)
    mapping = built_device("inverter_mppt").mapping()
    assert "inverter_three_phase_evt1_ground_fault" in {
        k for k, e in mapping.entities.items() if e.alarm and e.kind == "bool"
    }


def test_strings_are_read_once_and_writable_points_are_dangerous_commands() -> None:
    entities = built_device("device_1547").document["entities"]
    serial = entities["common_sn"]
    assert (serial["type"], serial["count"], serial["poll"]) == ("ascii", 16, "once")
    assert serial["sentinels"] == {0: "not implemented"}
    writable = {k: e for k, e in entities.items() if e.get("access") == "rw"}
    assert len(writable) > 50
    assert all(e["dangerous"] is True for e in writable.values())
    assert all(e["ha"]["entity_category"] == "config" for e in writable.values())
    assert not any("state_class" in e.get("ha", {}) for e in writable.values())
    protocol = built_device("device_1547").mapping().protocol
    assert (protocol.function_codes, protocol.addressing.offset) == ((3, 6, 16), 0)


@pytest.mark.parametrize("name", sorted(IMAGES))
def test_every_entity_is_planned_at_most_one_read_per_model(name: str) -> None:
    image = build_image(IMAGES[name])
    chain = walked(image)
    mapping = build_mapping(chain, image.registers).mapping()
    plan = plan_reads(mapping.points().values(), limits_for(mapping))
    assert plan.unplannable == ()
    assert all(r.function == 3 for r in plan.reads)
    # the models' registers, in reads (a curve far from its factors: one exponent read more)
    assert len(plan.reads) <= sum(-(-(m.length + 2) // 125) for m in chain.models)
    assert all(not b.before and b.after for b in plan.bracketed)  # factors at a model's top


def test_a_value_no_read_holds_with_its_scale_factor_is_kept_and_read_bracketed() -> None:
    built = built_device("inverter_123")  # model 129: four curves of 20 points, SFs at the top
    assert not [s for s in built.skipped if "scale factor" in s.reason or "no read" in s.reason]
    kept = built.document["entities"]
    assert {"lvrt_curve_3_v10", "lvrt_curve_3_v12", "lvrt_curve_4_v20"} <= set(kept)
    mapping = built.mapping()
    plan = plan_reads(mapping.points().values(), limits_for(mapping))
    bracketed = {key for b in plan.bracketed for key in b.keys}
    assert "lvrt_curve_3_v12" in bracketed and "lvrt_curve_4_v20" in bracketed
    assert "lvrt_curve_1_v1" not in bracketed  # near its factors: read with them
    exponents = sorted(b.exponent.address for b in plan.bracketed)  # V_SF and Tms_SF
    assert len(exponents) == len(plan.bracketed) == 2
    # side by side: both read again in one read after the curves, the pass's one extra read
    assert [(r.address, r.count) for r in plan.extra] == [(exponents[0], 2)]


@pytest.mark.parametrize("limit", [4, 50, 125])
def test_read_chain_reads_every_model_register_in_reads_within_the_limit(limit: int) -> None:
    image = build_image(IMAGES["device_1547"])
    chain = walked(image)
    asked: list[tuple[int, int]] = []

    async def read(address: int, count: int) -> list[int]:
        asked.append((address, count))
        return [image.registers[a] for a in range(address, address + count)]

    words = asyncio.run(read_chain(read, chain, limit))
    start, end = chain.models[0].address, chain.models[-1].end
    assert words == {a: image.registers[a] for a in range(start, end)}
    assert all(count <= limit for _, count in asked)
    assert len(asked) == sum(-(-(m.length + 2) // limit) for m in chain.models)
    assert build_mapping(chain, words).document == build_mapping(chain, image.registers).document


@pytest.mark.parametrize("allowed", [False, True])
def test_home_assistant_discovery_of_a_built_mapping(allowed: bool) -> None:
    mapping = built_device("inverter_mppt").mapping()
    device = DeviceInfo(
        id="inverter",
        name="Inverter",
        mapping=mapping,
        options={},
        bus="rs485",
        unit=1,
        allow_dangerous_writes=allowed,
        fast_interval=2.0,
        slow_interval=60.0,
    )
    [message] = build_discovery(device, Topics("modbus", "homeassistant"), Origin(), mode="device")
    components = json.loads(message.payload)["cmps"]
    assert set(mapping.entities) <= set(components)
    assert {"alarms", "alarm_events"} <= set(components)  # issue 25's alarms and events
    platforms = {c["platform"] for c in components.values()}
    assert {"sensor", "binary_sensor", "event"} <= platforms
    assert (components["common_da"]["platform"] == "number") is allowed  # dangerous
    energy = components["inverter_three_phase_wh"]
    assert (energy["device_class"], energy["state_class"], energy["unit_of_measurement"]) == (
        "energy",
        "total_increasing",
        "Wh",
    )
    assert components["inverter_three_phase_evt1_ground_fault"]["platform"] == "binary_sensor"


def test_a_model_twice_in_the_chain_gets_keys_of_its_own() -> None:
    device = {
        "models": [
            common("Two meters", "M-2"),
            built_model(203, seed=1),
            built_model(203, seed=2),
            {"ID": 65535, "L": 0},
        ]
    }
    image = build_image(device)
    chain = walked(image)
    built = build_mapping(chain, image.registers)
    entities = built.document["entities"]
    first, second = entities["ac_meter_abcn_w"], entities["ac_meter_abcn_2_w"]
    assert second["address"] - first["address"] == chain.models[2].address - chain.models[1].address
    assert second["scale_by"] == "ac_meter_abcn_2_w_sf"
    assert first["name"] != second["name"]
    models = reference_models(image, chain, device)
    assert differences(decoded(built, image), expected_values(built, models)) == []


def test_a_model_without_a_definition_is_left_out_with_the_reason() -> None:
    image = build_image(IMAGES["meter"])
    walked_chain = walked(image)
    unknown = ChainModel(64999, walked_chain.models[-1].end, 4)
    chain = Chain(walked_chain.base, (*walked_chain.models, unknown), walked_chain.common, 0)
    built = build_mapping(chain, image.registers)
    [left_out] = [s for s in built.skipped if not s.point]
    assert (left_out.model, left_out.address) == (64999, unknown.address)
    assert "no readable definition" in left_out.reason
    assert built.mapping().entities.keys() == build_mapping(walked_chain).mapping().entities.keys()


@pytest.mark.parametrize("name", sorted(IMAGES))
def test_the_yaml_of_a_built_mapping_loads_as_the_same_mapping(name: str) -> None:
    built = built_device(name)
    text = built.yaml()
    assert parse_mapping(text, f"{name}.yaml") == built.mapping()
    far = [s for s in built.skipped if s.reason != "padding"]
    assert all(f"model {s.model} at {s.address} {s.point}: {s.reason}" in text for s in far)
    assert "padding" not in text


def test_build_from_device_walks_reads_and_builds_within_the_read_limit() -> None:
    image = build_image(IMAGES["battery"], base=0)
    asked: list[int] = []

    async def read(address: int, count: int) -> list[int]:
        asked.append(count)
        if address not in image.registers:
            raise DeviceExceptionError(2, "illegal data address", "fail")
        return [image.registers[a] for a in range(address, address + count)]

    chain, built = asyncio.run(build_from_device(read, limits=WalkLimits(read_limit=40)))
    assert chain.base == 0 and max(asked) <= 40
    assert built.mapping().protocol.max_read_registers == 40
    assert built.document == build_mapping(chain, image.registers, read_limit=40).document


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ids=st.lists(st.sampled_from(MODELS), min_size=1, max_size=4),
    instances=st.integers(1, 3),
    seed=st.integers(0, 1000),
    base=st.sampled_from([40000, 50000, 0]),
)
def test_any_chain_of_models_builds_one_mapping_that_reads_like_pysunspec2(
    ids: list[int], instances: int, seed: int, base: int
) -> None:
    models = [
        _addresses_as_text(load_model(i).group, built_model(i, instances, seed + n))
        for n, i in enumerate(ids)
    ]
    device = {"models": [common("Any", "SN-9"), *models, {"ID": 65535, "L": 0}]}
    image = build_image(device, base)
    chain = walked(image)
    built = build_mapping(chain, image.registers)
    mapping = built.mapping()
    names = [e.name for e in mapping.entities.values()]
    assert len(set(names)) == len(names)
    assert plan_reads(mapping.points().values(), limits_for(mapping)).unplannable == ()
    wanted = expected_values(built, reference_models(image, chain, device))
    assert differences(decoded(built, image), wanted) == []


def test_a_fast_pass_reads_each_value_with_its_scale_factor() -> None:
    mapping = built_device("inverter_mppt").mapping()
    points = mapping.points()
    fast = [p for p in points.values() if p.entity.poll_spec == "fast"]
    assert "inverter_three_phase_w_sf" not in {p.key for p in fast}
    plan = plan_reads(fast, limits_for(mapping))
    assert plan.unplannable == ()
    for point in fast:
        if point.scale_source is not None:
            assert any(
                point.address in r.span and point.scale_source.address in r.span for r in plan.reads
            ), point.key


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    headers=st.lists(
        st.tuples(st.sampled_from([1, *MODELS, 64999]), st.integers(0, 260)), max_size=4
    ),
    seed=st.integers(0, 2**32 - 1),
)
def test_whatever_a_device_answers_the_builder_gives_a_valid_mapping_or_none(
    headers: list[tuple[int, int]], seed: int
) -> None:
    """Any model ids and lengths, any register content: models that do not lay out are
    left out with the reason, the rest validate; nothing raises."""
    rng = random.Random(seed)
    address, models = 40002, []
    for model_id, length in headers:
        models.append(ChainModel(model_id, address, length))
        address += 2 + length
    chain = Chain(40000, tuple(models), None, 0)
    words = {
        a: rng.choice([0, 1, 2, 0xFFFF, 0x8000, rng.randrange(0x10000)]) for a in range(address)
    }
    built = build_mapping(chain, words)
    laid_out = {s.model for s in built.sources.values()}
    left_out = {s.address for s in built.skipped if not s.point}
    for index, model in enumerate(models):  # each model: its entities, or why none
        assert (index in laid_out) != (model.address in left_out), (model, built.skipped)
    if built.document["entities"]:
        assert isinstance(built.mapping(), Mapping)


@pytest.mark.parametrize("model_id", [705, 707, 711, 803, 64410])
def test_counts_the_length_cannot_hold_are_refused_at_once(model_id: int) -> None:
    definition = load_model(model_id)
    counts = dict.fromkeys(definition.count_points, 0xFFFF)
    tracemalloc.start()
    try:
        with pytest.raises(ModelDefinitionError, match="need more than L 300"):
            layout(definition, 300, counts)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # refused from the counts alone: not 65535 x 65535 groups laid out first (that would
    # take gigabytes; the refusal takes what one model's definition does)
    assert peak < 5_000_000, peak


def test_a_batterys_state_of_charge_is_a_battery_sensor() -> None:
    entities = built_device("battery").document["entities"]
    for key in ("battery_soc", "storage_basic_chastate"):
        assert entities[key]["unit"] == "%"
        assert entities[key]["ha"] == {"device_class": "battery", "state_class": "measurement"}


@pytest.mark.parametrize("name", ["device_1547", "battery", "inverter_123"])
def test_a_writable_point_written_with_the_value_it_reads_writes_its_own_words(name: str) -> None:
    """Every setting: the value decoded, encoded again, is the same registers (FC06 for
    one, FC16 for more), scaled by the exponent the device holds."""
    image = build_image(IMAGES[name])
    built = build_mapping(walked(image), image.registers)
    words = {(Table.HOLDING, a): w for a, w in image.registers.items()}
    checked = 0
    for key, point in built.mapping().points().items():
        value = codec.decode(point, words)
        if not point.entity.writable or value is None or point.entity.kind == "text":
            continue
        [write] = codec.encode(point, value, words)
        assert write.function == (6 if point.count == 1 else 16), key
        assert write.address == point.address, key
        assert write.values == tuple(image.registers[a] for a in point.span), key
        checked += 1
    assert checked > 5
