"""The live view's admission rules (services/viewer/access.py): pure logic on request heads."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.errors import ConfigError
from services.viewer.access import origin_allowed, parse_head, refusal, token_ok
from services.viewer.contract import ViewerSettings

ALLOWED = ("https://app.foxglove.dev",)


def head(target: str = "/", origin: str | None = None) -> bytes:
    lines = [f"GET {target} HTTP/1.1", "Host: 127.0.0.1:8765", "Upgrade: websocket"]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


@pytest.mark.parametrize(
    ("origin", "ok"),
    [
        (None, True),  # a native client
        ("https://app.foxglove.dev", True),
        ("HTTPS://APP.FOXGLOVE.DEV/", True),
        ("https://evil.example.com", False),
        ("http://app.foxglove.dev", False),  # another scheme is another origin
        ("https://app.foxglove.dev.evil.example.com", False),
        ("https://app.foxglove.dev:444", False),
        ("null", False),  # a sandboxed page or a file:// page
        ("", False),
    ],
)
def test_origin_matching_is_exact(origin: str | None, ok: bool) -> None:
    assert origin_allowed(origin, ALLOWED) is ok


def test_no_token_required_under_the_default_profile() -> None:
    assert token_ok("/", None)


@pytest.mark.parametrize(
    ("target", "ok"),
    [
        ("/?token=s3cret", True),
        ("/?other=1&token=s3cret", True),
        ("/", False),
        ("/?token=", False),
        ("/?token=s3cre", False),
        ("/?token=s3cret&token=s3cret", False),  # ambiguous: refused
        ("/s3cret", False),
    ],
)
def test_token_must_be_the_query_parameter(target: str, ok: bool) -> None:
    assert token_ok(target, "s3cret") is ok


def test_refusal_says_why() -> None:
    assert refusal(head(), ALLOWED, None) is None
    assert refusal(head(origin="https://evil.example.com"), ALLOWED, None) == (
        "origin 'https://evil.example.com' is not in viewer.allowed_origins"
    )
    assert refusal(head("/?token=t"), ALLOWED, "t") is None
    assert refusal(head("/"), ALLOWED, "t") == "no valid viewer token"
    assert refusal(b"POST / HTTP/1.1\r\n\r\n", ALLOWED, None) == "not an HTTP GET request"
    assert refusal(b"\x16\x03\x01 garbage\r\n\r\n", ALLOWED, None) == "not an HTTP GET request"


def test_headers_are_case_insensitive() -> None:
    parsed = parse_head(b"GET /x HTTP/1.1\r\nORIGIN: https://a.b\r\n\r\n")
    assert parsed == ("/x", {"origin": "https://a.b"})


@pytest.mark.parametrize("bad", ["*", "app.foxglove.dev"])
def test_allowed_origins_are_origins(bad: str) -> None:
    with pytest.raises(ConfigError, match=r"viewer\.allowed_origins"):
        ViewerSettings(allowed_origins=(bad,))


def test_the_token_is_read_only_under_the_secure_profile(tmp_path: Path) -> None:
    from common.settings import ZenohSettings
    from services.viewer.service import viewer_token
    from stack.config import Config

    def config(auth: str) -> Config:
        return Config(zenoh=ZenohSettings(mode="client", auth=auth, credentials_dir=str(tmp_path)))

    assert viewer_token(config("none")) is None
    with pytest.raises(ConfigError, match=r"cannot read the viewer token .*viewer-token"):
        viewer_token(config("password"))
    token = tmp_path / "viewer-token"
    token.write_text("\n")
    token.chmod(0o600)
    with pytest.raises(ConfigError, match=r"viewer-token is empty"):
        viewer_token(config("password"))
    token.write_text("s3cret\n")
    assert viewer_token(config("password")) == "s3cret"
    token.chmod(0o644)  # others may read it: refused, with the fix
    with pytest.raises(ConfigError, match=rf"may be read by others: .*`chmod 600 {token}`"):
        viewer_token(config("password"))
