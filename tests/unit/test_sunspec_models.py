"""The SunSpec model definitions: every bundled model loads, and lengths and offsets equal
the ones pysunspec2 computes from the same files (its sunspec2.device.Model is the
reference)."""

from __future__ import annotations

from typing import Any

import pytest
from sunspec2 import device as ss_device

from bridge.sunspec.models import (
    HEADER,
    GroupDef,
    ModelDef,
    ModelDefinitionError,
    layout,
    load_model,
    model_ids,
    scale_factor,
)

IDS = model_ids()
REPEATING = [i for i in IDS if load_model(i).fixed_length is None]
FIXED = [i for i in IDS if i not in REPEATING]


def reference_points(group: Any, path: tuple[tuple[str, int], ...] = ()) -> list[Any]:
    """(path, name, offset) of every point of a pysunspec2 group, in its order."""
    found = [(path, name, p.offset) for name, p in group.points.items()]
    for name, sub in group.groups.items():
        instances = sub if isinstance(sub, list) else [sub]
        for g in instances:
            found += reference_points(g, (*path, (name, g.index or 0)))
    return found


def ours(model: ModelDef, length: int, counts: dict[str, int]) -> list[Any]:
    return [(p.path, p.point.name, p.offset) for p in layout(model, length, counts)]


def count_points(group: GroupDef) -> set[str]:
    names = {group.count} if isinstance(group.count, str) else set()
    for child in group.groups:
        names |= count_points(child)
    return names


def legacy_groups(group: GroupDef) -> list[GroupDef]:
    found = [g for g in group.groups if g.count == 0]
    for child in group.groups:
        found += legacy_groups(child)
    return found


def test_every_bundled_model_loads_with_every_point_type_known() -> None:
    assert len(IDS) > 100
    assert {1, 101, 103, 124, 160, 203, 701, 802}.issubset(IDS)
    for model_id in IDS:
        model = load_model(model_id)
        assert model.id == model_id
        first, second = model.group.points[:2]
        assert (first.name, first.value, second.name) == ("ID", model_id, "L")
        assert all(p.size > 0 for p in model.group.points)


@pytest.mark.parametrize("model_id", FIXED)
def test_a_fixed_model_s_length_and_offsets_are_pysunspec2_s(model_id: int) -> None:
    model = load_model(model_id)
    reference = ss_device.Model(model_id=model_id)
    assert not reference.error_info
    assert model.fixed_length == reference.len - HEADER
    assert ours(model, reference.len - HEADER, {}) == reference_points(reference)


@pytest.mark.parametrize("model_id", REPEATING)
@pytest.mark.parametrize("instances", [1, 3])
def test_repeating_groups_are_placed_as_pysunspec2_places_them(
    model_id: int, instances: int
) -> None:
    model = load_model(model_id)
    counts = dict.fromkeys(count_points(model.group), instances)
    legacy = legacy_groups(model.group)
    length = 0
    if legacy:
        top = model.group.points_length - HEADER
        length = top + instances * sum(g.points_length for g in legacy)
    reference = ss_device.Model(model_id=model_id, model_len=length, data=dict(counts))
    assert not reference.error_info
    length = reference.len - HEADER
    assert ours(model, length, counts) == reference_points(reference)
    paths = {p.path for p in layout(model, length, counts)}
    repeated = {name for path in paths for name, index in path if index == instances}
    assert repeated  # the last instance of some group is there


def test_model_160_has_one_module_group_per_twenty_registers() -> None:
    model = load_model(160)
    module = model.group.groups[0]
    assert (module.name, module.count, module.points_length) == ("module", 0, 20)
    placed = layout(model, 8 + 4 * 20)
    indices = sorted({path[0][1] for path in (p.path for p in placed) if path})
    assert indices == [1, 2, 3, 4]
    ids = [p for p in placed if p.point.name == "ID" and p.path]
    assert [p.offset for p in ids] == [10, 30, 50, 70]


def test_a_length_the_groups_do_not_fill_is_refused() -> None:
    with pytest.raises(ModelDefinitionError, match="no whole number"):
        layout(load_model(160), 8 + 20 + 7)
    with pytest.raises(ModelDefinitionError, match="L says"):
        layout(load_model(103), 51)
    with pytest.raises(ModelDefinitionError, match="needs point"):
        layout(load_model(705), 100)


def test_the_legacy_common_model_of_65_registers_has_no_pad() -> None:
    names = [p.point.name for p in layout(load_model(1), 65)]
    assert "Pad" not in names
    assert [p.point.name for p in layout(load_model(1), 66)][-1] == "Pad"


def test_points_keep_their_definition() -> None:
    model = load_model(103)
    w = model.group.point("W")
    assert (w.type, w.units, w.sf, w.access, w.mandatory) == ("int16", "W", "W_SF", "R", True)
    st = model.group.point("St")
    assert st.type == "enum16"
    assert {s.value: s.name for s in st.symbols}[4] == "MPPT"
    wh = model.group.point("WH")
    assert (wh.type, wh.size, wh.sf) == ("acc32", 2, "WH_SF")
    sn = load_model(1).group.point("SN")
    assert (sn.type, sn.size, sn.offset, sn.static) == ("string", 16, 50, True)
    assert load_model(123).group.point("WMaxLimPct").access == "RW"
    with pytest.raises(KeyError, match="no point 'Nope'"):
        model.group.point("Nope")


def test_an_unknown_model_is_a_clear_error() -> None:
    with pytest.raises(ModelDefinitionError, match="model 4242"):
        load_model(4242)


def reference_scale_factors(group: Any, model: Any) -> list[Any]:
    """(point offset, its scale factor's offset or exponent) as pysunspec2 resolves them
    (Point.get_value: the point's group first, then the model's top)."""
    found = []
    for p in group.points.values():
        if p.sf is not None:
            sf = group.points.get(p.sf) or model.points.get(p.sf)
            found.append((p.offset, sf.offset))
        elif p.sf_value is not None:
            found.append((p.offset, p.sf_value))
    for sub in group.groups.values():
        for g in sub if isinstance(sub, list) else [sub]:
            found += reference_scale_factors(g, model)
    return found


@pytest.mark.parametrize("model_id", IDS)
def test_scale_factors_resolve_as_pysunspec2_resolves_them(model_id: int) -> None:
    model = load_model(model_id)
    counts = dict.fromkeys(model.count_points, 2)
    assert set(model.count_points) == count_points(model.group)
    legacy = legacy_groups(model.group)
    length = model.group.points_length - HEADER + 2 * sum(g.points_length for g in legacy)
    reference = ss_device.Model(model_id=model_id, model_len=length if legacy else 0, data=counts)
    placed = layout(model, reference.len - HEADER, counts)
    ours_sf = []
    for p in placed:
        sf = scale_factor(p, placed)
        if sf is not None:
            ours_sf.append((p.offset, sf if isinstance(sf, int) else sf.offset))
            assert isinstance(sf, int) or sf.point.type == "sunssf"
    assert ours_sf == reference_scale_factors(reference, reference)


def test_a_scale_factor_that_is_not_placed_is_an_error() -> None:
    placed = layout(load_model(103), 50)
    watts = next(p for p in placed if p.point.name == "W")
    assert scale_factor(watts, placed) == next(p for p in placed if p.point.name == "W_SF")
    with pytest.raises(ModelDefinitionError, match="scale factor W_SF is not placed"):
        scale_factor(watts, [watts])
