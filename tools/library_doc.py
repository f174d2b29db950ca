"""Write docs/library.md: every shipped mapping's index entry, grouped by category then
manufacturer, with the independent sources each was cross-checked against (the points
compared and the disagreements, counted by tests/library/cross_check.py).

    python tools/library_doc.py > docs/library.md      (or: make docs)

tests/library/test_library_doc.py checks the file is current.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script: the tests' source data sits beside it
    sys.path.insert(0, str(ROOT))

from bridge.core.library import Category  # noqa: E402
from bridge.core.mapping import Mapping, shipped_library  # noqa: E402
from tests.library.cross_check import Comparison, compare  # noqa: E402
from tests.library.sources import SOURCES  # noqa: E402

REGENERATE = "python tools/library_doc.py > docs/library.md"
CHOSEN = (
    "**How the devices were chosen.** The kinds of device the people who run Home",
    "Assistant and Node-RED own (a DIN-rail meter, a hybrid inverter with its battery, a",
    "wallbox, a heat pump), and within each kind the models most projects already read:",
    "every library device is read by at least two independent projects among evcc's",
    "templates, volkszaehler/mbmd, openWB, OpenEMS, Victron's Modbus client and the",
    "community Home Assistant integration with the most users for its vendor (the",
    "*Sources compared* column), which is both the measure of how many people own it and",
    "the evidence its mapping is checked against. The meters are the ones inverters ship",
    "with or evcc users pick most (Eastron, Chint for Growatt, Huawei and SolaX, ABB,",
    "Carlo Gavazzi for Victron, ORNO); the inverters the vendors with the largest",
    "community integrations (Sungrow, Huawei, Growatt, Deye/Sunsynk, SolaX, GoodWe) and",
    "the Victron GX; SunSpec inverters (SMA, Fronius, SolarEdge, Kostal...) need no",
    "mapping here (`mapping: sunspec`). Install counts of community integrations were",
    "not used: they could not be read from where the library was built.",
)
HEADERS = (
    "Model",
    "`mapping:`",
    "Aliases",
    "Transports",
    "Register document",
    "Sources compared",
    "Points compared",
    "Disagreements",
    "Confidence",
    "`identify`",
)


def render_library_doc(library: dict[str, Mapping] | None = None) -> str:
    """The whole of docs/library.md for ``library`` (default: the shipped mappings)."""
    mappings = shipped_library() if library is None else library
    lines = [
        "# Device library",
        "",
        f"Generated from the mappings' `library:` blocks by `{REGENERATE}` (`make docs`);",
        "tests/library/test_library_doc.py checks it is current. Put a device in a config",
        "with its `mapping:` name; `modbus-mqtt-bridge mappings show NAME` prints its",
        "entities. *Points compared* counts, per independent source (tests/library/sources,",
        "facts transcribed as data), the points it shares with the mapping that",
        "tests/library/test_cross_check.py decodes from one register image both ways;",
        "each *disagreement* is listed below its table with the choice made and why.",
        "*`identify`* says whether `modbus-mqtt-bridge identify` can name the model",
        "(a device code or ID string) or only say a unit answers like it.",
        "",
        *CHOSEN,
        "",
        _summary(mappings),
    ]
    for category in Category:
        members = {n: m for n, m in mappings.items() if _category(m) is category}
        if members:
            lines += ["", f"## {_title(category)}", *_category_section(members)]
    return "\n".join(lines) + "\n"


def _summary(mappings: dict[str, Mapping]) -> str:
    counts = [
        f"{_title(c).lower()}: {n}"
        for c in Category
        if (n := sum(1 for m in mappings.values() if _category(m) is c))
    ]
    return f"{len(mappings)} devices ({', '.join(counts)})."


def _category_section(members: dict[str, Mapping]) -> list[str]:
    lines: list[str] = []
    for manufacturer in sorted({m.manufacturer for m in members.values()}, key=str.lower):
        mine = sorted(
            ((n, m) for n, m in members.items() if m.manufacturer == manufacturer),
            key=lambda item: item[1].model.lower(),
        )
        lines += ["", f"### {manufacturer}", "", _row(HEADERS), _row(["---"] * len(HEADERS))]
        lines += [_row(_cells(name, mapping)) for name, mapping in mine]
        for name, mapping in mine:
            lines += _choices(name, mapping)
    return lines


def _cells(name: str, mapping: Mapping) -> list[str]:
    library = mapping.library
    comparisons = _comparisons(name, mapping)
    compared = ", ".join(f"{c.source} {c.compared}" for c in comparisons)
    disagreements = sum(len(c.differences) for c in comparisons)
    return [
        mapping.model,
        f"`{name}`",
        ", ".join(library.aliases) if library is not None else "",
        ", ".join(mapping.protocol.transports),
        _document(mapping),
        ", ".join(c.source for c in comparisons) or "none",
        compared or "0",
        str(disagreements),
        library.confidence if library is not None else "",
        _identify(mapping),
    ]


def _choices(name: str, mapping: Mapping) -> list[str]:
    if mapping.library is None or not mapping.library.disagreements:
        return []
    lines = ["", f"Disagreements of `{name}` and the choices made:", ""]
    for row in mapping.library.disagreements:
        lines.append(f"- `{row.entity}` ({', '.join(row.sources)}): {_cell(row.choice)}")
    return lines


def _comparisons(name: str, mapping: Mapping) -> list[Comparison]:
    return [compare(mapping, definition) for definition in SOURCES.get(name, ())]


def _document(mapping: Mapping) -> str:
    source = mapping.source
    title = f"{source.title} {source.version}" if source.version else source.title
    return f"[{_cell(title)}]({source.url})" if source.url else _cell(title)


def _identify(mapping: Mapping) -> str:
    """What ``identify`` can say of a unit of this model: its fingerprint's strength."""
    found = mapping.fingerprint
    if found is None:
        return "no fingerprint"
    return "identifies" if found.identifies else "answers like"


def _category(mapping: Mapping) -> Category | None:
    return mapping.library.category if mapping.library is not None else None


def _title(category: Category) -> str:
    return category.value.replace("_", " ").capitalize()


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def _row(cells: Iterable[str]) -> str:
    return "| " + " | ".join(cells) + " |"


if __name__ == "__main__":
    sys.stdout.write(render_library_doc())
