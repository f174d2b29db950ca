"""The documentation stays true: docs/mappings.md, docs/config.md and examples/mappings.

Conventions of the ```yaml blocks in docs/mappings.md (its introduction says the same):

- first line ``# examples/mappings/NAME.yaml ...``: the block is that file, exactly;
- first line ``# fragment``: a piece of a mapping, either entities (``key: {name, address,
  ...}``) or top-level sections (``protocol``, ``options``, ``status``, ``entities``),
  wrapped into a minimal mapping by ``wrap_fragment`` and validated;
- first line ``# fragment (invalid)``: a mistake shown on purpose: it must be refused, with
  every message quoted in its comments (``"a second whole value ..."``);
- first line ``# config [PATH]``: a config file (saved at PATH, relative to the repository),
  validated with the mappings it names, relative to its folder;
- anything else: a whole mapping, validated as it stands.

Every file in examples/mappings/ loads for every option combination, plans within its
limits, decodes what the simulator holds, builds discovery, and is polled over loopback
TCP from the simulator by the real engine with the same values.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from pydantic import BaseModel

from bridge import config as config_module
from bridge.cli.config_doc import EXAMPLE, REGENERATE, duration_fields, render_config_doc
from bridge.config import Config, load_config_data
from bridge.core.address import Addressing
from bridge.core.codec import decode, encode
from bridge.core.discovery import DeviceInfo, Origin, build_device_discovery
from bridge.core.discovery_entity import platform_of
from bridge.core.entity import Entity, PollClass, Presentation, RawRange, Variant
from bridge.core.fingerprint import Fingerprint, Probe
from bridge.core.library import Disagreement, Library
from bridge.core.mapping import Mapping, Source, load_mapping, parse_mapping
from bridge.core.planner import limits_for, plan_reads
from bridge.core.protocol import (
    ExceptionMeaning,
    Keepalive,
    OptionSpec,
    Protocol,
    Reserved,
    Segment,
    SerialDefaults,
)
from bridge.core.simulation import initial_image
from bridge.core.topics import Topics
from bridge.core.yaml_source import parse_yaml
from bridge.errors import MappingError
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.integration.harness import config, running, serving_tcp, tcp_bus

ROOT = Path(__file__).resolve().parent.parent
MAPPINGS_DOC = ROOT / "docs" / "mappings.md"
CONFIG_DOC = ROOT / "docs" / "config.md"
EXAMPLES = sorted((ROOT / "examples" / "mappings").glob("*.yaml"))
BLOCKS = re.findall(r"```yaml\n(.*?)```", MAPPINGS_DOC.read_text(encoding="utf-8"), re.DOTALL)

MINIMAL: dict[str, Any] = {
    "manufacturer": "Docs",
    "model": "Fragment",
    "description": "a fragment of docs/mappings.md",
    "source": {"title": "docs/mappings.md"},
}
TOP_LEVEL = frozenset(Mapping.model_fields)
_FILE_BLOCK = re.compile(r"^# (examples/mappings/[\w.-]+\.yaml)\b")
_QUOTED = re.compile(r'#.*?"([^"]+)"')


def kind_of(block: str) -> str:
    first = block.split("\n", 1)[0]
    if _FILE_BLOCK.match(first):
        return "file"
    for marker, kind in (
        ("# fragment (invalid)", "invalid"),
        ("# fragment", "fragment"),
        ("# config", "config"),
    ):
        if first.startswith(marker):
            return kind
    return "mapping"


def blocks_of(kind: str) -> list[str]:
    return [block for block in BLOCKS if kind_of(block) == kind]


def block_id(block: str) -> str:
    lines = [line for line in block.splitlines() if line and not line.startswith("#")]
    return lines[0].strip()[:40] if lines else "empty"


def wrap_fragment(text: str) -> str:
    """A whole mapping around a fragment: its top-level sections merged into a minimal
    header, or its entities put under ``entities``. A fragment without entities gets one
    placeholder register, readable with the function codes the fragment allows."""
    data = yaml.safe_load(text)
    assert isinstance(data, dict), "a fragment is a YAML mapping"
    whole = MINIMAL | (data if set(data) <= TOP_LEVEL else {"entities": data})
    if "entities" not in whole:
        whole["entities"] = {"placeholder": _placeholder(whole.get("protocol", {}))}
    return yaml.safe_dump(whole, allow_unicode=True, sort_keys=False)


def _placeholder(protocol: dict[str, Any]) -> dict[str, Any]:
    codes = protocol.get("function_codes", [3])
    table = {3: "holding", 4: "input", 1: "coil", 2: "discrete"}
    chosen = next(table[code] for code in (3, 4, 1, 2) if code in codes)
    offset = protocol.get("addressing", {}).get("offset", 0)
    return {"name": "Placeholder", "table": chosen, "address": 0xFFF0 - offset}


# --- docs/mappings.md -------------------------------------------------------------------


def test_the_doc_has_every_kind_of_block() -> None:
    kinds = {kind_of(block) for block in BLOCKS}
    assert kinds == {"file", "fragment", "invalid", "config", "mapping"}
    assert len(blocks_of("fragment")) >= 20


@pytest.mark.parametrize("block", blocks_of("mapping"), ids=block_id)
def test_whole_mappings_load(block: str) -> None:
    parse_mapping(block, "docs/mappings.md")


@pytest.mark.parametrize("block", blocks_of("fragment"), ids=block_id)
def test_fragments_validate_inside_a_minimal_mapping(block: str) -> None:
    parse_mapping(wrap_fragment(block), "docs/mappings.md fragment")


@pytest.mark.parametrize("block", blocks_of("invalid"), ids=block_id)
def test_mistakes_shown_are_refused_with_the_quoted_message(block: str) -> None:
    with pytest.raises(MappingError) as refused:
        parse_mapping(wrap_fragment(block), "docs/mappings.md mistake")
    quoted = _QUOTED.findall(block)
    assert quoted, "an invalid fragment quotes the message it expects"
    for message in quoted:
        assert message in str(refused.value)


@pytest.mark.parametrize("block", blocks_of("config"), ids=block_id)
def test_config_blocks_are_valid_with_their_mappings(block: str) -> None:
    """``# config PATH ...``: the file as saved at PATH, whose folder its mapping paths
    are relative to (else the repository root)."""
    first = block.split("\n", 1)[0].removeprefix("# config").split()
    path = ROOT / (first[0] if first else "config.yaml")
    assert path.parent.is_dir(), f"{path.parent} does not exist"
    loaded = load_config_data(parse_yaml(block, "docs/mappings.md"), path)
    assert loaded.config.devices


@pytest.mark.parametrize("block", blocks_of("file"), ids=block_id)
def test_example_files_are_shown_exactly(block: str) -> None:
    match = _FILE_BLOCK.match(block)
    assert match
    assert (ROOT / match.group(1)).read_text(encoding="utf-8") == block


def test_every_example_is_in_the_doc() -> None:
    shown = {m.group(1) for block in blocks_of("file") if (m := _FILE_BLOCK.match(block))}
    assert shown == {f"examples/mappings/{path.name}" for path in EXAMPLES}


def test_every_mapping_field_is_documented() -> None:
    text = MAPPINGS_DOC.read_text(encoding="utf-8")
    models: list[type[BaseModel]] = [Mapping, Source, OptionSpec, Entity, Variant, RawRange]
    models += [Presentation, Protocol, Addressing, ExceptionMeaning, Keepalive, Segment]
    models += [Reserved, SerialDefaults, Fingerprint, Probe, Library, Disagreement]
    prose = re.sub(r"```.*?```", "", text, flags=re.DOTALL)
    spans = " ".join(re.findall(r"`([^`]+)`", prose))
    for model in models:
        for field in model.model_fields:
            assert re.search(rf"\b{field}\b", spans), f"{model.__name__}.{field}"


# --- docs/config.md ------------------------------------------------------------------------


def test_config_doc_is_generated_from_the_schema() -> None:
    assert CONFIG_DOC.read_text(encoding="utf-8") == render_config_doc(), (
        f"docs/config.md is out of date: run `make docs` (or `{REGENERATE}`)"
    )


def test_config_doc_covers_every_field() -> None:
    text = render_config_doc()
    assert "## `bridge`" in text
    assert "| `health_interval` | duration | `60s` |" in text
    assert "| `transport` | `rtu` \\| `ascii` | **required** |" in text
    assert "| `transport` | `tcp` \\| `rtu-over-tcp` | **required** |" in text
    for name in duration_fields(Config):
        for field in getattr(config_module, name).model_fields:
            assert f"| `{field}` |" in text, f"{name}.{field}"


def test_config_doc_example_is_valid(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MQTT_PASSWORD", "secret")
    monkeypatch.setenv("BRIDGE_WEB_TOKEN", "a-long-enough-web-token")
    loaded = load_config_data(parse_yaml(EXAMPLE, "config_doc.EXAMPLE"), ROOT / "config.yaml")
    assert [d.id for d in loaded.config.devices] == ["borehole_pump", "genset", "oven"]
    assert loaded.config.bridge.metrics.enabled
    assert loaded.config.bridge.web.token_value() == "a-long-enough-web-token"


# --- examples/mappings/*.yaml -------------------------------------------------------------


def combinations(mapping: Mapping) -> list[dict[str, str]]:
    names = list(mapping.options)
    choices = [mapping.options[n].choices for n in names]
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*choices)]


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_loads_plans_and_simulates_for_every_option(path: Path) -> None:
    mapping = load_mapping(path)
    limits = limits_for(mapping)
    for options in combinations(mapping):
        points = mapping.points(options)
        plan = plan_reads(points.values(), limits)
        assert plan.unplannable == (), options
        for read in plan.reads:
            assert read.count <= limits.max_count(read.table), read
        image = initial_image(mapping, points)
        for key, point in points.items():
            if point.entity.readable:
                value = decode(point, image)
                assert value is not None or point.entity.enum is not None, key
            if point.entity.press is not None:
                assert encode(point, "PRESS", image), key


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
@pytest.mark.parametrize("allow", [False, True], ids=["guarded", "dangerous-allowed"])
def test_example_builds_discovery(path: Path, allow: bool) -> None:
    mapping = load_mapping(path)
    for options in combinations(mapping):
        device = DeviceInfo("example", "Example", mapping, options, "bus", 1, allow, 2.0, 60.0)
        payload = build_device_discovery(device, Topics("modbus"), Origin())
        assert payload["device"]["manufacturer"] == mapping.manufacturer
        shown = {k for k, e in mapping.active(options).items() if platform_of(e, allow)}
        assert shown <= set(payload["cmps"]), options


@pytest.mark.asyncio
@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
async def test_example_is_polled_from_the_simulator(path: Path) -> None:
    mapping = load_mapping(path)
    sim = Simulator([SimulatedUnit(1, mapping)], tick=0.0)
    async with serving_tcp(sim) as port:
        device = {"id": "example", "bus": "tcp", "unit": 1, "mapping": str(path)}
        engine = Engine(config([tcp_bus(port)], [device]))
        async with running(engine, pollers=False):
            poller = engine.devices["example"]
            await poller.poll((PollClass.FAST, PollClass.SLOW, PollClass.ONCE))
            assert poller.health.online is True
            assert poller.health.errors == 0
            readable = [k for k, p in poller.points.items() if p.entity.readable]
            for key in readable:
                assert poller.values[key] == sim.value(1, key), key


# --- links ---------------------------------------------------------------------------------

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lowercase, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors_of(text: str) -> set[str]:
    prose = re.sub(r"```.*?```", "", text, flags=re.DOTALL)
    headings = re.findall(r"^#{1,6} (.+)$", prose, flags=re.MULTILINE)
    return {slug(h) for h in headings} | set(re.findall(r'<a id="([^"]+)"></a>', text))


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_point_at_files_and_headings_that_exist(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    for target in _LINK.findall(text):
        if target.startswith(("http://", "https://", "mailto:")):
            continue
        path, _, anchor = target.partition("#")
        linked = (page.parent / path).resolve() if path else page
        assert linked.exists(), f"{page.name}: {target}"
        if anchor:
            assert anchor in anchors_of(linked.read_text(encoding="utf-8")), (
                f"{page.name}: {target}"
            )
