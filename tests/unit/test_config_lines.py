"""bridge.config.lines: Myers' opcodes rebuild the second text and are never longer than
difflib's; the three-way merge keeps the user's layout outside the edit."""

from __future__ import annotations

import difflib

from hypothesis import given
from hypothesis import strategies as st

from bridge.config.lines import above_blank_lines, merge_lines, opcodes

texts = st.lists(st.sampled_from(["a", "b", "c", "", "# c"]), max_size=40)


def _cost(ops: list[tuple[str, int, int, int, int]]) -> int:
    return sum(i2 - i1 + j2 - j1 for tag, i1, i2, j1, j2 in ops if tag != "equal")


@given(texts, texts)
def test_opcodes_rebuild_the_second_text_at_most_as_long_as_difflib(
    a: list[str], b: list[str]
) -> None:
    ops = opcodes(a, b)
    rebuilt: list[str] = []
    i = j = 0
    for tag, i1, i2, j1, j2 in ops:
        assert (i1, j1) == (i, j)
        assert tag != "equal" or a[i1:i2] == b[j1:j2]
        rebuilt += b[j1:j2]
        i, j = i2, j2
    assert (i, j, rebuilt) == (len(a), len(b), b)
    reference = difflib.SequenceMatcher(None, a, b, autojunk=False).get_opcodes()
    assert _cost(ops) <= _cost(reference)


def test_long_texts_compare_by_their_differences() -> None:
    a = [f"    bus: gw {i % 3}\n" for i in range(20000)]
    b = ["first\n", *a[1:10000], "new\n", *a[10001:-1], "last\n"]
    assert [op for op in opcodes(a, b) if op[0] != "equal"] == [
        ("replace", 0, 1, 0, 1),
        ("replace", 10000, 10001, 10000, 10001),
        ("replace", 19999, 20000, 19999, 20000),
    ]
    different = [f"other {i}\n" for i in range(20000)]  # past the search's bound: one hunk
    assert opcodes(a, different) == [("replace", 0, 20000, 0, 20000)]


BASE = ["a: 1\n", "b: {x: 1, y: 2}\n", "c: 3\n", "d: 4\n"]
USER = ["a: 1\n", "b: {x: 1,\n", "    y: 2}   # two lines\n", "c: 3\n", "d: 4\n"]


def test_an_edit_away_from_the_users_layout_keeps_it() -> None:
    edited = ["a: 1\n", "b: {x: 1, y: 2}\n", "c: 3\n", "d: 5\n"]
    assert merge_lines(USER, BASE, edited) == [*USER[:4], "d: 5\n"]


def test_an_edit_inside_the_users_layout_takes_the_edited_lines() -> None:
    edited = ["a: 1\n", "b: {x: 9, y: 2}\n", "c: 3\n", "d: 4\n"]
    assert merge_lines(USER, BASE, edited) == ["a: 1\n", "b: {x: 9, y: 2}\n", "c: 3\n", "d: 4\n"]


def test_lines_both_add_at_one_place_come_the_users_first() -> None:
    user = [*BASE, "# the end\n"]
    edited = [*BASE, "e: 5\n"]
    assert merge_lines(user, BASE, edited) == [*BASE, "# the end\n", "e: 5\n"]


def test_added_lines_go_above_the_blank_line_that_closes_an_entry() -> None:
    base = ["- id: a\n", "  unit: 1\n", "\n", "# b\n", "- id: b\n"]
    edited = ["- id: a\n", "  unit: 1\n", "\n", "# b\n", "  enabled: false\n", "- id: b\n"]
    assert above_blank_lines(base, edited) == [
        "- id: a\n",
        "  unit: 1\n",
        "  enabled: false\n",
        "\n",
        "# b\n",
        "- id: b\n",
    ]


def test_a_new_entry_is_spaced_as_the_one_before_and_a_removed_last_takes_its_space() -> None:
    base = ["items:\n", "  - a: 1\n", "\n", "  - b: 2\n"]
    assert above_blank_lines(base, [*base, "  - c: 3\n"]) == [*base, "\n", "  - c: 3\n"]
    assert above_blank_lines(base, base[:3]) == base[:2]
    tight = ["items:\n", "  - a: 1\n", "  - b: 2\n"]
    assert above_blank_lines(tight, [*tight, "  - c: 3\n"]) == [*tight, "  - c: 3\n"]
