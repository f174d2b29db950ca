"""bridge.config.store, property: any sequence of edits to a commented example keeps every
comment line, in order, and each step reads back as the bridge loads it with exactly the
values the edit set (names of any printable text)."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from bridge.config import load_config
from bridge.config.edits import parse_change
from bridge.config.store import ConfigStore

EXAMPLES = Path(__file__).parents[2] / "examples"
DEVICES = ("borehole_pump", "booster_starter")

names = st.text(
    st.characters(codec="utf-8", exclude_categories=("Cc", "Cs", "Zl", "Zp")),
    min_size=1,
    max_size=30,
)
SECONDS = {"30s": 30, "2min": 120, 90: 90, 0.5: 0.5}
# never one unit: the booster starts at unit 2, so the pump never moves there
UNITS = {"borehole_pump": (3, 100), "booster_starter": (101, 247)}


def edits(device_id: str) -> st.SearchStrategy[tuple[str, dict[str, Any]]]:
    fields = st.one_of(
        st.fixed_dictionaries({"name": names}),
        st.fixed_dictionaries({"unit": st.integers(*UNITS[device_id])}),
        st.fixed_dictionaries({"enabled": st.booleans()}),
        st.fixed_dictionaries({"poll.slow": st.sampled_from(list(SECONDS))}),
        st.fixed_dictionaries({"allow_dangerous_writes": st.booleans()}),
    )
    return st.tuples(st.just(device_id), fields)


steps = st.lists(st.sampled_from(DEVICES).flatmap(edits), min_size=1, max_size=4)


def _comments(text: str) -> list[str]:
    return [line.split("#", 1)[1] for line in text.splitlines() if "#" in line]


# the same examples on every run (a CI run is repeatable), and no explain phase: its line
# tracer makes a failing example minutes slow on Python 3.11
@settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink],
    suppress_health_check=[HealthCheck.too_slow],
)
@given(steps)
def test_edits_keep_every_comment_and_read_back_as_set(
    plan: list[tuple[str, dict[str, Any]]],
) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "config.yaml"
        shutil.copyfile(EXAMPLES / "rtu-serial.yaml", path)
        comments = _comments(path.read_text(encoding="utf-8"))
        store = ConfigStore.open(path)
        for device_id, fields in plan:
            change = parse_change({"kind": "edit_device", "id": device_id, "set": fields})
            applied = store.apply(change)
            assert applied.loaded.config == load_config(path).config
            device = next(d for d in applied.loaded.config.devices if d.id == device_id)
            for key, value in fields.items():
                field, _, sub = key.partition(".")
                got = getattr(getattr(device, field), sub) if sub else getattr(device, field)
                assert got == (SECONDS[value] if sub else value), (key, got, value)
        assert _comments(path.read_text(encoding="utf-8")) == comments
