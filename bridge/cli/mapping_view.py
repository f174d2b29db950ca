"""What ``mappings show`` prints around the entities table: the mapping's index entry
(document, category, aliases, transports, sources, disagreements) and its fingerprint;
and which shipped mapping a model name or alias means (``named``)."""

from __future__ import annotations

from typing import TextIO

from bridge.core.fingerprint import Probe
from bridge.core.mapping import Mapping, shipped_library
from bridge.errors import MappingError


def named(ref: str) -> str | None:
    """The shipped mapping whose model or one of whose aliases is ``ref`` (case and
    spaces, dashes ignored): ``SDM630`` is ``eastron_sdm630``. None when none is; an error
    naming them when several are."""
    wanted = _plain(ref)
    found = [
        name
        for name, mapping in shipped_library().items()
        if wanted in {_plain(mapping.model), *(_plain(a) for a in _aliases(mapping))}
    ]
    if len(found) > 1:
        raise MappingError(ref, [f"several shipped mappings are called so: {', '.join(found)}"])
    return found[0] if found else None


def _aliases(mapping: Mapping) -> tuple[str, ...]:
    return mapping.library.aliases if mapping.library is not None else ()


def _plain(text: str) -> str:
    return "".join(c for c in text.lower() if c.isalnum())


def print_header(mapping: Mapping, out: TextIO) -> None:
    """Manufacturer, model, description, the document and the library's index entry."""
    print(f"{mapping.manufacturer} {mapping.model}: {mapping.description}", file=out)
    source = mapping.source
    document = ", ".join(p for p in (source.title, source.version, source.url) if p)
    print(f"document: {document}", file=out)
    print(f"transports: {', '.join(mapping.protocol.transports)}", file=out)
    library = mapping.library
    if library is None:
        return
    print(f"category: {library.category.value}", file=out)
    if library.aliases:
        print(f"aliases: {', '.join(library.aliases)}", file=out)
    print(f"sources: {', '.join(library.sources) or 'none cross-checked'}", file=out)
    print(f"confidence: {library.confidence}", file=out)
    for row in library.disagreements:
        print(f"disagreement {row.entity} ({', '.join(row.sources)}): {row.choice}", file=out)


def print_fingerprint(mapping: Mapping, out: TextIO) -> None:
    """The probes ``identify`` reads, one line each (or that there are none)."""
    found = mapping.fingerprint
    if found is None:
        print("fingerprint: none (identify cannot tell this model)", file=out)
        return
    kind = "identifies" if found.identifies else "answers like (identifies: false)"
    print(f"fingerprint: {kind}{f' - {found.note}' if found.note else ''}", file=out)
    for probe in found.probes:
        print(f"  probe {_where(probe)}: {_test(probe)}, weight {probe.weight}", file=out)


def _where(probe: Probe) -> str:
    if probe.entity is not None:
        return probe.entity
    table = probe.table.value if probe.table is not None else "holding"
    return f"{table} {probe.address} x{probe.count}"


def _test(probe: Probe) -> str:
    tests = {
        "equals": probe.equals,
        "min": probe.min,
        "max": probe.max,
        "one of": list(probe.one_of) if probe.one_of else None,
        "ascii": probe.ascii,
    }
    shown = [f"{name} {value}" for name, value in tests.items() if value is not None]
    shown += [name for name, flag in (("unit id", probe.unit), ("answers", probe.answers)) if flag]
    return ", ".join(shown) + (" (required)" if probe.required else "")
