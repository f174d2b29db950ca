"""Lines of text compared and merged: what ``bridge.config.document`` needs to put an
edit into the user's own text. Pure functions on lists of lines.

``opcodes`` is difflib's format from Myers' algorithm (time grows with the number of
differences, not with the square of the file: a config of thousands of near-identical
lines compares in milliseconds); past ``MAX_DIFFERENCES``, or ``MAX_WORK`` line
comparisons, the texts count as different throughout. ``merge_lines`` is a
three-way merge of the edit into the user's layout.
"""

from __future__ import annotations

from collections.abc import Sequence

MAX_DIFFERENCES = 400  # inserted plus deleted lines past which two texts are "all different"
MAX_WORK = 2_000_000  # line comparisons one search may make (about a second)
Opcode = tuple[str, int, int, int, int]  # difflib's (tag, i1, i2, j1, j2)
Hunk = tuple[int, int, int, list[str]]  # (start, end) in the base, side (0 user, 1 edit), lines


def opcodes(a: Sequence[str], b: Sequence[str]) -> list[Opcode]:
    """How ``a`` becomes ``b``, as difflib's SequenceMatcher.get_opcodes() says it."""
    n, m = len(a), len(b)
    head = 0
    while head < min(n, m) and a[head] == b[head]:
        head += 1
    tail = 0
    while tail < min(n, m) - head and a[n - 1 - tail] == b[m - 1 - tail]:
        tail += 1
    moves = _moves(a[head : n - tail], b[head : m - tail])
    result: list[Opcode] = [("equal", 0, head, 0, head)] if head else []
    i = j = head
    for equal, deleted, inserted in _runs(moves):
        if equal:
            result.append(("equal", i, i + equal, j, j + equal))
        else:
            tag = "replace" if deleted and inserted else "delete" if deleted else "insert"
            result.append((tag, i, i + deleted, j, j + inserted))
        i, j = i + (equal or deleted), j + (equal or inserted)
    if tail:
        result.append(("equal", n - tail, n, m - tail, m))
    return result


def _moves(a: Sequence[str], b: Sequence[str]) -> str:
    """Myers' shortest edit script: ``=`` keep, ``-`` delete, ``+`` insert, in order."""
    n, m = len(a), len(b)
    if not n or not m:
        return "-" * n + "+" * m
    frontier: dict[int, int] = {1: 0}
    trace: list[dict[int, int]] = []
    work = 0
    for depth in range(min(n + m, MAX_DIFFERENCES) + 1):
        trace.append(dict(frontier))
        for k in range(-depth, depth + 1, 2):
            down = k == -depth or (k != depth and frontier[k - 1] < frontier[k + 1])
            x = frontier[k + 1] if down else frontier[k - 1] + 1
            y = start = x - k
            while x < n and y < m and a[x] == b[y]:
                x, y = x + 1, y + 1
            work += y - start + 1
            frontier[k] = x
            if x >= n and y >= m:
                return _backtrack(trace, n, m)
        if work > MAX_WORK:
            break
    return "-" * n + "+" * m  # too different to be worth the search


def _backtrack(trace: list[dict[int, int]], n: int, m: int) -> str:
    x, y = n, m
    moves: list[str] = []
    for depth in range(len(trace) - 1, -1, -1):
        frontier, k = trace[depth], x - y
        down = k == -depth or (k != depth and frontier[k - 1] < frontier[k + 1])
        previous_k = k + 1 if down else k - 1
        previous_x = frontier[previous_k]
        previous_y = previous_x - previous_k
        while x > previous_x and y > previous_y:
            moves.append("=")
            x, y = x - 1, y - 1
        if depth:
            moves.append("+" if x == previous_x else "-")
            x, y = previous_x, previous_y
    return "".join(reversed(moves))


def _runs(moves: str) -> list[tuple[int, int, int]]:
    """Runs of kept lines, or of changed ones: (kept, deleted, inserted), one of them 0s."""
    runs: list[tuple[int, int, int]] = []
    start = 0
    while start < len(moves):
        end = start
        same = moves[start] == "="
        while end < len(moves) and (moves[end] == "=") == same:
            end += 1
        run = moves[start:end]
        runs.append((len(run), 0, 0) if same else (0, run.count("-"), run.count("+")))
        start = end
    return runs


def changed_lines(a: Sequence[str], b: Sequence[str]) -> int:
    """How many lines differ between ``a`` and ``b``."""
    return sum(max(i2 - i1, j2 - j1) for tag, i1, i2, j1, j2 in opcodes(a, b) if tag != "equal")


def above_blank_lines(base: list[str], edited: list[str]) -> list[str]:
    """``edited`` with its added and removed lines placed as a person would: added lines
    above the blank and comment lines before them (ruamel writes a new key or entry after
    the blank line and the comments that close the one before, which belong to what
    follows), a blank line before a new list entry if the entry before it has one; removed
    lines leave the comments and blank lines that close them (ruamel removes them with the
    key before), and a removed last entry the blank line before it."""
    result: list[str] = []
    for tag, i1, i2, j1, j2 in opcodes(base, edited):
        ends = i2 == len(base) or not base[i2].strip()
        if tag == "delete" and _entry(base[i1]) and ends and result and not result[-1].strip():
            result.pop()  # the removed entry's separator
        if tag == "delete":
            result += _closing(base[i1:i2])
        if tag != "insert":
            result += edited[j1:j2]
            continue
        keep = len(result)
        while keep > 0 and _remark(result[keep - 1]):
            keep -= 1
        added = edited[j1:j2]
        if _entry(added[0]) and _spaced_entry(result[:keep], added[0]):
            added = ["\n", *added]
        result[keep:keep] = added
    return result


def _closing(removed: list[str]) -> list[str]:
    """The comment and blank lines that end ``removed`` (an entry's blank lines excepted):
    they lead to what follows it."""
    count = 0
    while count < len(removed) and _remark(removed[len(removed) - 1 - count]):
        count += 1
    closing = removed[len(removed) - count :] if count < len(removed) else []
    return [line for line in closing if line.strip()] if _entry(removed[0]) else closing


def _remark(line: str) -> bool:
    return not line.strip() or line.lstrip().startswith("#")


def _entry(line: str) -> bool:
    return line.lstrip().startswith("- ")


def _spaced_entry(before: list[str], entry: str) -> bool:
    """The list entry before ``entry`` (same indentation) has a blank line before it."""
    indent = len(entry) - len(entry.lstrip())
    for index in range(len(before) - 1, 0, -1):
        line = before[index]
        if line.strip() and len(line) - len(line.lstrip()) < indent:
            return False  # out of the list
        if _entry(line) and len(line) - len(line.lstrip()) == indent:
            return not before[index - 1].strip()
    return False


def merge_lines(user: list[str], base: list[str], edited: list[str]) -> list[str]:
    """The changes from ``base`` to ``edited`` made to ``user`` (``base`` in the user's
    layout). Where a change meets lines the user laid out otherwise, the edited lines of
    that stretch win; lines both add at one place come the user's first."""
    edit_ops = opcodes(base, edited)
    hunks: list[Hunk] = [
        (i1, i2, 0, user[j1:j2]) for tag, i1, i2, j1, j2 in opcodes(base, user) if tag != "equal"
    ]
    hunks += [(i1, i2, 1, edited[j1:j2]) for tag, i1, i2, j1, j2 in edit_ops if tag != "equal"]
    result: list[str] = []
    position = 0
    for start, end, lines, members in _clusters(sorted(hunks, key=lambda h: h[:3])):
        result += base[position:start]
        if members > 1:  # both changed this stretch: the edit's version of it
            result += edited[_mapped(edit_ops, start) : _mapped(edit_ops, end)]
        else:
            result += lines
        position = end
    return result + base[position:]


def _clusters(hunks: list[Hunk]) -> list[tuple[int, int, list[str], int]]:
    """Hunks (sorted) grouped where they change the same base lines: (start, end, the lines
    of a lone hunk, how many hunks)."""
    clusters: list[tuple[int, int, list[str], int]] = []
    for start, end, _, lines in hunks:
        if clusters:
            c_start, c_end, c_lines, count = clusters[-1]
            if start < c_end or (start == end and c_start < start < c_end):
                clusters[-1] = (c_start, max(c_end, end), c_lines, count + 1)
                continue
        clusters.append((start, end, lines, 1))
    return clusters


def _mapped(ops: Sequence[Opcode], position: int) -> int:
    """The line of the edited text at ``position`` of the base (a hunk's edge)."""
    for tag, i1, i2, j1, j2 in ops:
        if i1 <= position <= i2:
            if tag == "equal":
                return j1 + position - i1
            return j1 if position == i1 else j2
    return sum(j2 - j1 for _, _, _, j1, j2 in ops)
