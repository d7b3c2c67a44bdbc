"""``gcs-utm config mqtt-acl``: the ACL the broker runs with is the one the bridge's tests run
a real mosquitto with (adapters.mqtt.acl), for the configured prefix and UTM user."""

from __future__ import annotations

import pytest

from adapters.mqtt.acl import mosquitto_acl
from gcs_utm.cli import main


def test_cli_prints_the_acl_for_the_prefix_and_user(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["config", "mqtt-acl", "--prefix", "utm1", "--utm-user", "svc"]) == 0
    out = capsys.readouterr().out
    assert out == mosquitto_acl("utm1", utm_user="svc")
    assert "user svc\ntopic readwrite utm1/#\n" in out
    assert "pattern write utm1/operators/%u/answers\n" in out


@pytest.mark.parametrize("argv", [["--prefix", "a/#"], ["--utm-user", "a b"]])
def test_cli_refuses_a_prefix_or_user_that_is_not_one_topic_level(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["config", "mqtt-acl", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "is not a valid topic level" in err
