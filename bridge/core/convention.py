"""How a mapping presents its device to people: names, identity and enabled defaults. Pure.

The rules of docs/mappings.md ("Names" and "Which entities are enabled") for the shipped
library (the package's ``mappings/``), as ``location: message`` rows
(``checks.check_conventions``): errors in its tests (tests/mappings), warnings from
``mappings validate`` for a file in that folder. A user's or an imported mapping is never
checked against them: its names are the user's (a battery's "BMS voltage" stays so), and
no advice may send a user to edit the installed package. None protects a device (entity
ids come from keys, writes are guarded by ``dangerous`` and the config).

- a name reads as words: no internal key in it (a word with ``_``), no shouting (a word
  of three or more capitals that is not a known abbreviation, ``ABBREVIATIONS``), and no
  two entities a device shows at once share one;
- the manufacturer reads as a company's name (``Generic`` when the manual names none),
  not as a note about it (``Unknown (...)``);
- an entity shown as diagnostic (``entity_category: diagnostic``, or a dangerous
  setting, which Home Assistant shows read-only until the device allows dangerous
  writes) is disabled by default; one enabled anyway says why in ``ha.enabled_reason``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from collections.abc import Mapping as AnyMapping

from bridge.core.entity import Entity
from bridge.core.variant import active_entities

# Words a shipped mapping's name may write in capitals: abbreviations people read as such.
# Add one here on purpose; a manual's habit of printing parameter names in capitals is not
# a reason.
ABBREVIATIONS = frozenset(
    {
        "ASCII",
        "ATS",  # automatic transfer switch
        "CAN",
        "CPU",
        "CRC",
        "DOL",  # direct on line (a motor started without a drive)
        "DVCC",  # distributed voltage and current control (Victron)
        "ECU",  # engine control unit
        "EEPROM",
        "ESS",  # energy storage system (Victron's grid-interactive battery control)
        "FOC",  # field-oriented control
        "IGBT",
        "LED",
        "MAC",
        "MOSFET",
        "MPPT",  # maximum power point tracking
        "MTU",  # the engine maker
        "NTC",
        "PCB",
        "PID",
        "PLC",
        "PLL",  # phase-locked loop (grid synchronisation)
        "PTC",
        "PWM",
        "RMS",
        "RPM",
        "RTU",
        "SCR",
        "SSD",
        "TCP",
        "THD",  # total harmonic distortion (energy meters)
        "UAB",  # phase-to-phase voltages as genset controllers print them
        "UBC",
        "UCA",
        "USB",
        "VFD",
    }
)
_WORD = re.compile(r"\w*_\w*|[^\W_]+")  # words; a word with "_" is one word
_PLACEHOLDER = re.compile(r"\b(unknown|unidentified|unnamed|not named|n/a|tbd)\b|[()?]", re.I)


def convention_problems(
    manufacturer: str, entities: AnyMapping[str, Entity], combinations: Iterable[dict[str, str]]
) -> Iterator[str]:
    """Every break of the presentation rules in a mapping's ``manufacturer`` and
    ``entities`` (whose addresses, options and variants are valid); names are compared
    among the entities present together, for each of the option ``combinations``."""
    if _PLACEHOLDER.search(manufacturer):
        yield (
            f"manufacturer: {manufacturer!r} does not read as a company's name "
            "(write 'Generic' when the manual names none, and what you know in a comment)"
        )
    for key, entity in entities.items():
        for location, shown in _presented(key, entity):
            yield from (f"{location}.name: {p}" for p in name_problems(shown.name))
            problem = default_problem(shown)
            if problem is not None:
                yield f"{location}.ha.enabled: {problem}"
    yield from _shared_names(entities, combinations)


def name_problems(name: str) -> list[str]:
    """Why ``name`` does not read well to a person, if it does not."""
    problems = []
    for word in _WORD.findall(name):
        if "_" in word:
            problems.append(f"{word!r} reads as an internal key: write words ({name!r})")
        elif _shouts(word):
            problems.append(
                f"{word!r} is written in capitals: write it as a word, or add the "
                f"abbreviation to bridge/core/convention.py ({name!r})"
            )
    return problems


def _shouts(word: str) -> bool:
    """A word of three or more capitals (one with digits is a code: HGM6110, 0004H)."""
    return word.isalpha() and len(word) >= 3 and word.isupper() and word not in ABBREVIATIONS


def default_problem(entity: Entity) -> str | None:
    """Why the entity's enabled default breaks the rule, if it does."""
    if entity.shown_as_diagnostic and entity.enabled_by_default and not entity.ha.enabled_reason:
        what = "a dangerous setting (shown read-only, as diagnostic)"
        if entity.ha.entity_category == "diagnostic":
            what = "a diagnostic entity"
        return f"{what} is disabled by default: say why it is enabled in ha.enabled_reason"
    return None


def _presented(key: str, entity: Entity) -> Iterator[tuple[str, Entity]]:
    """The entity and each of its variants applied, with their locations (only called on
    a mapping whose variants validate: ``checks.check_conventions``)."""
    yield f"entities.{key}", entity
    for index, variant in enumerate(entity.variants):
        yield f"entities.{key}.variants.{index}", entity.with_variant(variant)


def _shared_names(
    entities: AnyMapping[str, Entity], combinations: Iterable[dict[str, str]]
) -> Iterator[str]:
    """Two entities a device shows at once under one name (``combinations`` name every
    option, so no default is needed)."""
    seen: set[str] = set()
    for chosen in combinations:
        owners: dict[str, str] = {}
        for key, entity in active_entities(entities, chosen).items():
            first = owners.setdefault(entity.name.casefold(), key)
            row = f"entities.{key}.name: {entity.name!r} is also the name of {first!r}"
            if first != key and row not in seen:
                seen.add(row)
                yield row
