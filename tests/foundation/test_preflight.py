"""``config check`` says ok only for what ``serve`` will start with (issue 21, item 8): link
strings, signing keys, TLS files and cross-key ranges are checked up front, by the same rules
``serve`` applies, and ``serve`` refuses the same files with the same one-line error."""

from __future__ import annotations

import shutil
import socket
import subprocess
from pathlib import Path

import pytest

from gcs_utm.cli import main
from gcs_utm.preflight import problems
from gcs_utm.settings import Settings, load_settings

KEY = "ab" * 32


def _check(tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    path = tmp_path / "c.toml"
    path.write_text(text)
    code = main(["config", "check", str(path)])
    out, err = capsys.readouterr()
    return code, out + err


@pytest.mark.parametrize(
    ("text", "key", "fragment"),
    [
        ('[mavlink]\nlinks = ["udpin:127.0.0.1"]\n', "mavlink", "links: connection string"),
        (
            '[mavlink]\nlinks = ["udpin:127.0.0.1:14550", "carrier-pigeon:1:2"]\n',
            "mavlink",
            "unknown 'carrier-pigeon'",
        ),
        ('[mavlink]\nlinks = ["udpout:127.0.0.1:99999"]\n', "mavlink", "port: out of range"),
        ('[mavlink]\nsigning_keys = { "1" = "xyz" }\n', "mavlink", "signing_keys.1"),
        (
            f'[mavlink]\nsigning_keys = {{ "1" = "{KEY[:-2]}" }}\n',
            "mavlink",
            "32 bytes (64 hex digits)",
        ),
        (f'[mavlink]\nsigning_keys = {{ "0" = "{KEY}" }}\n', "mavlink", "1..255"),
        (
            "[mqtt]\nbackoff_initial_s = 60.0\nbackoff_max_s = 5.0\n",
            "mqtt.backoff_initial_s",
            "at most mqtt.backoff_max_s",
        ),
        (
            "[adsb]\nreconnect_initial_s = 50.0\nreconnect_max_s = 2.0\n",
            "adsb.reconnect_initial_s",
            "at most",
        ),
        ('[mqtt]\ntopic_prefix = "utm/#"\n', "mqtt.topic_prefix", "wildcards"),
        (
            '[mqtt.tls]\nenabled = true\nca_path = "/nonexistent/ca.pem"\n',
            "mqtt.tls.ca_path",
            "does not exist",
        ),
    ],
)
def test_config_check_refuses_what_serve_cannot_use(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, key: str, fragment: str
) -> None:
    code, said = _check(tmp_path, text, capsys)
    assert code == 2, said
    assert f"c.toml: {key}: " in said and fragment in said, said
    assert said.count("\n") == 1
    # serve refuses the same file with the same line, before opening any link or store
    db = tmp_path / "never.sqlite"
    assert main(["serve", "--config", str(tmp_path / "c.toml"), "--db", str(db)]) == 2
    _out, err = capsys.readouterr()
    assert f"{key}: " in err and not db.exists()


def test_tls_files_must_load_as_the_client_loads_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    garbage = tmp_path / "ca.pem"
    garbage.write_text("-----BEGIN CERTIFICATE-----\nnot base64\n-----END CERTIFICATE-----\n")
    code, said = _check(tmp_path, f'[mqtt.tls]\nenabled = true\nca_path = "{garbage}"\n', capsys)
    assert code == 2 and "mqtt.tls.ca_path: expected a PEM CA certificate file" in said
    code, said = _check(tmp_path, f'[mqtt.tls]\nenabled = true\ncert_path = "{garbage}"\n', capsys)
    assert code == 2 and "mqtt.tls.key_path: mutual TLS needs both" in said
    code, said = _check(tmp_path, f'[mqtt.tls]\nenabled = true\nca_path = "{tmp_path}"\n', capsys)
    assert code == 2 and "is a directory" in said


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl CLI absent")
def test_a_real_certificate_and_key_pass(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert, key = tmp_path / "c.pem", tmp_path / "k.pem"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=gcs-utm-test",
            "-keyout",
            str(key),
            "-out",
            str(cert),
        ],
        check=True,
        capture_output=True,
    )
    text = (
        f'[mqtt.tls]\nenabled = true\nca_path = "{cert}"\ncert_path = "{cert}"\n'
        f'key_path = "{key}"\n'
    )
    code, said = _check(tmp_path, text, capsys)
    assert code == 0 and "ok" in said, said
    # a key that is not the certificate's is refused
    other = tmp_path / "k2.pem"
    subprocess.run(
        ["openssl", "genrsa", "-out", str(other), "2048"], check=True, capture_output=True
    )
    code, said = _check(tmp_path, text.replace(str(key), str(other)), capsys)
    assert code == 2 and "do not load together" in said


def test_defaults_and_good_values_have_no_problems(tmp_path: Path) -> None:
    assert problems(Settings()) == []
    path = tmp_path / "ok.toml"
    path.write_text(
        '[mavlink]\nlinks = ["udpin:0.0.0.0:14550", "tcp:127.0.0.1:5760", "/dev/ttyUSB0,57600"]\n'
        f'signing_keys = {{ "1" = "{KEY}" }}\n'
        "[mqtt]\nbackoff_initial_s = 1.0\nbackoff_max_s = 1.0\n"
    )
    settings = load_settings(path)
    assert settings.mavlink.links[1] == "tcp:127.0.0.1:5760"


def test_config_check_and_serve_refuse_a_link_that_cannot_be_opened_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A link listed twice, a port another program holds, an address not on this host, an
    unresolvable peer: ``config check`` names the link in one line, and ``serve`` refuses to
    start with the same line (it used to end in tracebacks)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as held:
        held.bind(("127.0.0.1", 0))
        port = held.getsockname()[1]
        cases = [
            (
                '"udpin:127.0.0.1:14999", "udp:127.0.0.1:14999"',
                "links[1]: 'udp:127.0.0.1:14999' is the same link",
            ),
            (f'"udpin:127.0.0.1:{port}"', f"links[0]: 'udpin:127.0.0.1:{port}' cannot be bound"),
            ('"udpin:0.0.0.0:0", "udpin:192.0.2.1:0"', "links[1]: 'udpin:192.0.2.1:0' cannot be"),
            ('"udpout:no-such-host.invalid:14550"', "does not resolve"),
        ]
        for links, fragment in cases:
            code, said = _check(tmp_path, f"[mavlink]\nlinks = [{links}]\n", capsys)
            assert code == 2 and said.count("\n") == 1 and fragment in said, said
        code = main(
            [
                "serve",
                "--config",
                str(tmp_path / "c.toml"),
                "--headless",
                "--db",
                str(tmp_path / "d"),
            ]
        )
        _, err = capsys.readouterr()
        assert code == 2 and err.count("\n") == 1 and "does not resolve" in err, err
        code, said = _check(tmp_path, '[mavlink]\nlinks = ["udpin:127.0.0.1:0"]\n', capsys)
        assert code == 0 and "ok" in said
