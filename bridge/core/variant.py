"""Option-dependent entities: which a device has, and as which variant. Pure.

A mapping declares ``options`` (a pump's sensor type, a drive's control mode); an entity
with ``when`` exists only for the option values it names, and the first of its
``variants`` whose ``when`` matches replaces some of its fields. These functions work on
the parts (entities, option specs), so the model (``mapping``) and the checks of it
(``checks``, ``convention``) share them without depending on each other.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from collections.abc import Mapping as AnyMapping

from bridge.core.entity import Entity
from bridge.core.protocol import OptionSpec

MAX_COMBINATIONS = 256  # option combinations the checks look at, at most


def when_matches(when: AnyMapping[str, str | list[str]], chosen: AnyMapping[str, str]) -> bool:
    """True when every option named in ``when`` has one of the listed values."""
    for option, wanted in when.items():
        values = [wanted] if isinstance(wanted, str) else wanted
        if chosen.get(option) not in values:
            return False
    return True


def apply_variants(entity: Entity, chosen: AnyMapping[str, str]) -> Entity:
    """The entity as configured: the first variant matching the option values applies."""
    for variant in entity.variants:
        if when_matches(variant.when, chosen):
            return entity.with_variant(variant)
    return entity


def active_entities(
    entities: AnyMapping[str, Entity], chosen: AnyMapping[str, str]
) -> dict[str, Entity]:
    """The entities present for the option values ``chosen``, their variants applied."""
    return {
        key: apply_variants(entity, chosen)
        for key, entity in entities.items()
        if when_matches(entity.when, chosen)
    }


def option_combinations(options: AnyMapping[str, OptionSpec]) -> Iterator[dict[str, str]]:
    """Every combination of option values (the first ``MAX_COMBINATIONS``)."""
    names = list(options)
    choices = [options[name].choices for name in names]
    for combo in itertools.islice(itertools.product(*choices), MAX_COMBINATIONS):
        yield dict(zip(names, combo, strict=True))
