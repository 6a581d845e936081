"""Who may open the live view: pure checks on a WebSocket upgrade request's head.

A request with an ``Origin`` header (every browser sends one) is let in only if that origin is
in ``viewer.allowed_origins``; one without (native apps: Foxglove desktop, scripts) is let in.
Under the secure profile the request's URL must also carry ``?token=<viewer-token>``
(docs/security.md, "The live view").
"""

from __future__ import annotations

import hmac
from urllib.parse import parse_qs, urlsplit

MAX_HEAD_BYTES = 8192  # an upgrade request's head is a few hundred bytes


def parse_head(head: bytes) -> tuple[str, dict[str, str]] | None:
    """The request target and the headers (names lower-cased) of an HTTP request head, or None
    if it is not one."""
    try:
        text = head.decode("latin-1")
    except UnicodeDecodeError:
        return None
    lines = text.split("\r\n")
    parts = lines[0].split(" ")
    if len(parts) != 3 or parts[0] != "GET" or not parts[2].startswith("HTTP/"):
        return None
    headers: dict[str, str] = {}
    for line in lines[1:]:
        if not line:
            continue
        name, sep, value = line.partition(":")
        if not sep:
            return None
        headers[name.strip().lower()] = value.strip()
    return parts[1], headers


def normal_origin(origin: str) -> str:
    """An origin as compared: lower-case, no trailing slash."""
    return origin.strip().rstrip("/").lower()


def origin_allowed(origin: str | None, allowed: tuple[str, ...]) -> bool:
    """No Origin (a native client) passes; a browser's passes only if it is listed exactly."""
    if origin is None:
        return True
    return normal_origin(origin) in {normal_origin(a) for a in allowed}


def token_ok(target: str, token: str | None) -> bool:
    """True when no token is required, or the target's ``token`` query parameter equals it."""
    if token is None:
        return True
    given = parse_qs(urlsplit(target).query).get("token", [])
    return len(given) == 1 and hmac.compare_digest(given[0].encode(), token.encode())


def refusal(head: bytes, allowed: tuple[str, ...], token: str | None) -> str | None:
    """Why the request with this head is refused, or None to let it through."""
    parsed = parse_head(head)
    if parsed is None:
        return "not an HTTP GET request"
    target, headers = parsed
    if not origin_allowed(headers.get("origin"), allowed):
        return f"origin {headers['origin']!r} is not in viewer.allowed_origins"
    if not token_ok(target, token):
        return "no valid viewer token"
    return None
