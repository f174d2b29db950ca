"""identify's pure part: the reads planned, the ranking, the snippet and the JSON."""

from __future__ import annotations

from pathlib import Path

import yaml

from bridge.config import load_config_data
from bridge.core.fingerprint import MAX_PROBES, probe_read
from bridge.core.identify import (
    MAX_MATCHES,
    Identity,
    SunSpecDevice,
    probe_plan,
    rank,
    request_bound,
    snippet,
)
from bridge.core.mapping import builtin_mapping_names, builtin_mapping_path, load_mapping
from bridge.core.request import Read

LIBRARY = {name: load_mapping(builtin_mapping_path(name)) for name in builtin_mapping_names()}


def test_every_shipped_mapping_has_a_fingerprint_and_the_plan_is_within_the_bound() -> None:
    assert all(m.fingerprint is not None for m in LIBRARY.values())
    plan = probe_plan(LIBRARY)
    assert len(plan) == len(set(plan))
    assert 1 + 3 + len(plan) <= request_bound(LIBRARY, 0, 3) == 1 + 3 + MAX_PROBES * len(LIBRARY)
    assert request_bound(LIBRARY, 46, 3) == 1 + max(46, 3 + MAX_PROBES * len(LIBRARY))
    walk = 3 + MAX_PROBES * len(LIBRARY) + 1  # a SunSpec walk may take more than the probes
    assert request_bound(LIBRARY, walk, 3) == walk + 1


def test_a_read_two_mappings_share_is_planned_once() -> None:
    twin = LIBRARY["p2_vfd"].model_copy()
    assert len(probe_plan({"a": LIBRARY["p2_vfd"], "b": twin})) == len(probe_plan({"a": twin}))


def text_matching(pattern: str) -> str:
    """A text the shell pattern matches: ``*`` empty, ``?`` one letter, a ``[set]`` its first."""
    text, i = "", 0
    while i < len(pattern):
        if pattern[i] == "[":
            end = pattern.index("]", i)
            text, i = text + pattern[i + 1], end + 1
            continue
        text += {"*": "", "?": "X"}.get(pattern[i], pattern[i])
        i += 1
    return text


def text_words(text: str, count: int) -> tuple[int, ...]:
    """``text`` as ``count`` registers, two characters each, high byte first, NUL padded."""
    raw = text.encode("ascii").ljust(count * 2, b"\0")[: count * 2]
    return tuple(int.from_bytes(raw[i : i + 2], "big") for i in range(0, count * 2, 2))


def answers_for(name: str, unit: int) -> dict[Read, tuple[int, ...] | None]:
    """What a unit that passes every probe of ``name`` reads (a value each test accepts)."""
    mapping = LIBRARY[name]
    assert mapping.fingerprint is not None
    answers: dict[Read, tuple[int, ...] | None] = {}
    for probe in mapping.fingerprint.probes:
        read = probe_read(probe, mapping.entities, mapping.protocol)
        if probe.ascii is not None:
            answers[read] = text_words(text_matching(probe.ascii), read.count)
            continue
        first = (
            probe.equals
            if probe.equals is not None
            else probe.one_of[-1]
            if probe.one_of
            else unit
            if probe.unit
            else probe.min or 0
        )
        answers[read] = (first,) + (0,) * (read.count - 1)
    return answers


def test_each_seed_ranks_first_on_its_own_answers() -> None:
    for name, mapping in LIBRARY.items():
        found = rank(LIBRARY, 9, answers_for(name, 9))
        assert found[0].mapping == name
        assert len(found) <= MAX_MATCHES
        assert found[0].failed == ()
        assert found[0].like is not mapping.fingerprint.identifies  # type: ignore[union-attr]


def test_nothing_answered_matches_nothing() -> None:
    assert rank(LIBRARY, 9, {}) == ()
    refused = dict.fromkeys(probe_plan(LIBRARY))
    assert rank(LIBRARY, 9, refused) == ()


def test_the_nastec_address_register_must_read_the_unit() -> None:
    answers = answers_for("nastec_vasco", 9)
    assert rank(LIBRARY, 9, answers)[0].level == "high"
    assert all(m.mapping != "nastec_vasco" for m in rank(LIBRARY, 10, answers))


def test_a_sunspec_device_is_described_by_its_common_model() -> None:
    found = SunSpecDevice(40000, "SMA", "SB5.0", "1.2", "3001", (1, 101, 120, 160))
    identity = Identity(3, "rs485", found, (), 17)
    assert identity.best == "sunspec"
    assert identity.summary() == (
        "SunSpec device SMA SB5.0 (serial 3001; version 1.2; models 1, 101, 120, 160; "
        "marker at 40000)"
    )
    assert identity.as_dict()["sunspec"] == {
        "base": 40000,
        "manufacturer": "SMA",
        "model": "SB5.0",
        "version": "1.2",
        "serial_number": "3001",
        "models": [1, 101, 120, 160],
        "note": None,
    }
    bare = SunSpecDevice(0, note="model 7 at 2: more than 40 models")
    assert bare.describe() == "SunSpec device unnamed (marker at 0)"


def test_the_snippet_is_a_valid_device_entry() -> None:
    text = snippet("rs485", 7, "vacon_nx")
    assert text == "- id: vacon_nx_7\n  bus: rs485\n  unit: 7\n  mapping: vacon_nx\n"
    bus = {"id": "rs485", "transport": "rtu", "port": "/dev/ttyUSB0"}
    loaded = load_config_data({"buses": [bus], "devices": yaml.safe_load(text)}, Path("c.yaml"))
    assert [d.mapping for d in loaded.config.devices] == ["vacon_nx"]


def test_identity_json() -> None:
    matches = rank(LIBRARY, 4, answers_for("soft_starter", 4))
    identity = Identity(4, "tcp", None, matches, 22)
    document = identity.as_dict()
    assert document["summary"].startswith("answers like Generic Motor soft-starter controller")
    assert document["summary"].endswith("low")
    assert document["config"] == snippet("tcp", 4, "soft_starter")
    assert document["matches"][0]["answers_like"] is True
    assert document["sunspec"] is None
    sunspec = Identity(4, "tcp", SunSpecDevice(0), (), 3).as_dict()
    assert sunspec["summary"] == "SunSpec device unnamed (marker at 0)"
    assert sunspec["sunspec"]["base"] == 0
    assert sunspec["config"] == snippet("tcp", 4, "sunspec")
    nothing = Identity(4, "tcp", None, (), 22, "stopped").as_dict()
    assert nothing["config"] is None
    assert nothing["summary"] == "answers, but matches no mapping of the library"
