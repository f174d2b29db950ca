"""``modbus-mqtt-bridge identify`` against the real simulator on loopback TCP."""

from __future__ import annotations

import json
import textwrap
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.core.mapping import shipped_library
from bridge.modbus.identify import request_bound
from tests.integration.harness import simulator
from tests.test_commission_cli import Served, run


@pytest.fixture
def served() -> Iterator[Served]:
    sim = simulator((2, "soft_starter"), (5, "vacon_nx"))
    with Served(sim) as serving:
        yield serving


def test_identify_json_tells_each_unit_and_writes_nothing(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(
        capsys, "identify", "--bus", served.bus, "--units", "1-5", "--timeout", "0.3", "--json"
    )
    assert code == 0, err
    document = json.loads(out)
    assert document["probed"] == [1, 2, 3, 4, 5]
    assert document["max_requests_per_unit"] == request_bound(shipped_library())
    found = {item["unit"]: item for item in document["found"]}
    assert sorted(found) == [2, 5]
    assert found[2]["matches"][0]["mapping"] == "soft_starter"
    assert found[2]["matches"][0]["answers_like"] is True
    assert found[5]["config"] == "- id: vacon_nx_5\n  bus: bus\n  unit: 5\n  mapping: vacon_nx\n"
    assert "unit 2: answers like" in err
    assert served.sim.writes == []
    per_unit = Counter(unit for unit, _, _ in served.sim.requests)
    assert set(per_unit) == {2, 5}
    assert all(count <= request_bound(shipped_library()) for count in per_unit.values())


def test_identify_prints_the_answer_and_the_snippet(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run(capsys, "identify", "--bus", served.bus, "--unit", "5")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].startswith("unit 5: answers like Vacon NX")
    assert lines[0].endswith(" low")
    assert "      mapping: vacon_nx" in lines


def test_identify_of_an_absent_unit_exits_1(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(capsys, "identify", "--bus", served.bus, "--unit", "9", "--timeout", "0.2")
    assert (code, out) == (1, "")
    assert "no unit answered" in err
    assert 9 not in {unit for unit, _, _ in served.sim.requests}


def test_unit_or_units_is_required(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["identify", "--bus", "tcp://127.0.0.1:1"])
    assert exited.value.code == 2
    assert "one of the arguments --unit --units is required" in capsys.readouterr().err


def test_help_states_the_bound(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    assert f"({request_bound(shipped_library())} with the shipped ones)" in " ".join(
        capsys.readouterr().out.split()
    )


def test_the_readme_shows_what_identify_prints(capsys: pytest.CaptureFixture[str]) -> None:
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    start = readme.index("    unit 3: answers like")
    shown = readme[start : readme.index("mapping: soft_starter\n", start) + 22]
    with Served(simulator((3, "soft_starter"))) as serving:
        code, out, _ = run(capsys, "identify", "--bus", serving.bus, "--unit", "3")
    assert code == 0
    assert out == textwrap.dedent(shown)
