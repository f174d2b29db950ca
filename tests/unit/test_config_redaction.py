"""bridge.config.redaction: secrets hidden in config text line by line (a conflict diff
shows which lines changed, never a value), in data (views) and in change summaries."""

from __future__ import annotations

import datetime

import pytest

from bridge.config.edits import SECRET_KEYS, SECRET_MARK
from bridge.config.model import DeviceConfig, WebConfig
from bridge.config.mqtt import MqttConfig
from bridge.config.redaction import change_rows, public_data, redact_text

M = SECRET_MARK


@pytest.mark.parametrize(
    ("line", "shown"),
    [
        ("  password: hunter2", f"  password: {M}"),
        ('  password: "ab#cd, x}"   # quoted', f"  password: {M}   # quoted"),
        ("  - password: pass#word", f"  - password: {M}"),
        ("    token_env: SOME_VAR # the env", f"    token_env: {M} # the env"),
        ("  password_file: /run/secrets/mqtt", f"  password_file: {M}"),
        ("  - {id: d, password: 'it''s', unit: 1}", f"  - {{id: d, password: {M}, unit: 1}}"),
        (
            "  web: {enabled: true, token: abcdefghijklmnopq}",
            f"  web: {{enabled: true, token: {M}}}",
        ),
        (
            "  url: mqtt://user:pw@host:1883   # login",
            f"  url: mqtt://user:{M}@host:1883   # login",
        ),
        ("  passwords_note: keep", "  passwords_note: keep"),
        ("  - id: g   # password: in a comment", "  - id: g   # password: in a comment"),
        ("  username: bridge", "  username: bridge"),
    ],
)
def test_a_secret_on_its_line_is_hidden(line: str, shown: str) -> None:
    assert redact_text(line + "\n") == shown + "\n"


def test_the_lines_that_continue_a_secret_are_hidden_and_counted() -> None:
    text = (
        "  - password: |\n      12345\n      67890\n    unit: 2\n"
        '  - password: "multi\n      line"\n    id: f\n'
    )
    assert redact_text(text) == (
        f"  - password: |\n      {M}\n      {M}\n    unit: 2\n"
        f"  - password: {M}\n      {M}\n    id: f\n"
    )
    assert len(redact_text(text + "\r\n").splitlines()) == len((text + "\r\n").splitlines())


def test_every_secret_field_of_the_models_is_a_secret_key() -> None:
    for model in (MqttConfig, DeviceConfig, WebConfig):
        secret = {
            name
            for name, field in model.model_fields.items()
            if "SecretStr" in str(field.annotation)
        }
        assert secret, model
        for name in secret:
            assert {name, f"{name}_file", f"{name}_env"} <= SECRET_KEYS


def test_views_and_summaries_hide_secrets() -> None:
    before = {
        "mqtt": {"url": ["mqtt://a:pw1@h1", "mqtt://a:pw1@h2"]},
        "devices": [{"id": "d", "password": "1"}],
    }
    after = {"mqtt": {"url": ["mqtt://a:pw2@h1"]}, "devices": [{"id": "d", "password": "2"}]}
    assert public_data(before) == {
        "mqtt": {"url": [f"mqtt://a:{M}@h1", f"mqtt://a:{M}@h2"]},
        "devices": [{"id": "d", "password": M}],
    }
    rows = change_rows(before, after)
    assert rows == [
        f'mqtt.url.0: "mqtt://a:{M}@h1" (changed)',
        f'mqtt.url.1: "mqtt://a:{M}@h2" -> (removed)',
        f'devices.d.password: "{M}" (changed)',
    ]


def test_a_view_holds_json_types_only() -> None:  # YAML reads 2024-01-02 as a date
    view = public_data({"devices": [{"id": "d", "name": datetime.date(2024, 1, 2), "unit": 1}]})
    assert view == {"devices": [{"id": "d", "name": "2024-01-02", "unit": 1}]}
