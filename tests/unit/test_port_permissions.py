"""The advice for a serial port the bridge may not open (EACCES): which group owns it and
how to join it on the host or in a container, where the host's group id is what counts."""

from __future__ import annotations

import stat

from bridge.modbus.transport import permission_hint

CHAR_0660 = stat.S_IFCHR | 0o660


def test_not_in_the_group_names_the_gid_for_group_add() -> None:
    hint = permission_hint(20, " (dialout)", CHAR_0660, 10001, {10001})
    assert "group 20 (dialout)" in hint
    assert "uid 10001 is not in it" in hint
    assert "--group-add 20" in hint
    assert "group_add: ['20']" in hint


def test_a_host_group_the_container_does_not_know_by_name() -> None:
    hint = permission_hint(986, "", CHAR_0660, 10001, {10001, 20})
    assert "group 986 and uid 10001" in hint
    assert "--group-add 986" in hint


def test_in_the_group_but_the_mode_leaves_the_group_out() -> None:
    hint = permission_hint(20, " (dialout)", stat.S_IFCHR | 0o600, 10001, {10001, 20})
    assert "crw-------" in hint
    assert "0660" in hint
    assert "--group-add" not in hint


def test_in_the_group_with_group_read_write() -> None:
    hint = permission_hint(20, " (dialout)", CHAR_0660, 10001, {20})
    assert "is in the port's group 20 (dialout)" in hint
