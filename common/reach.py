"""Saying where a command-line client looked when it reached nothing.

``zstack query``, ``zstack record``, ``zstack play`` (and compare's replay) and the e-stop
command join a running stack; when nothing answers, the user must learn what was tried
(endpoint, mode, prefix, principal and auth) and the likely fix, not only that nothing answered.
Pure text apart from :func:`connected`, which asks the session whether any router or peer is
linked to it.
"""

from __future__ import annotations

import time

import zenoh

from common.clock import mono_s
from common.settings import ZenohSettings

# How often to look at the session's links while waiting for the first one.
LINK_POLL_S = 0.05


def describe(settings: ZenohSettings, prefix: str, principal: str) -> str:
    """``endpoint tcp/127.0.0.1:7447 (peer mode, no auth), prefix 'stack'``, and the principal
    and credentials folder when the session authenticates."""
    auth = "no auth" if settings.auth == "none" else f"{settings.auth} auth as {principal!r} "
    if settings.auth != "none":
        auth += f"from {settings.credentials_path}"
    return f"endpoint {settings.endpoint} ({settings.mode} mode, {auth}), prefix {prefix!r}"


def connected(session: zenoh.Session, timeout_s: float = 0.0) -> bool:
    """True once ``session`` is linked to a router or a peer, waiting up to ``timeout_s``."""
    deadline = mono_s() + timeout_s
    while True:
        info = session.info
        if any(True for _ in info.routers_zid()) or any(True for _ in info.peers_zid()):
            return True
        if mono_s() >= deadline:
            return False
        time.sleep(LINK_POLL_S)


def hint(settings: ZenohSettings, *, linked: bool, ready: frozenset[str] = frozenset()) -> str:
    """The likely fix when nothing of the stack answered; ``ready``: the services whose health
    token was seen under the prefix."""
    if not linked:
        fix = (
            "nothing is listening there: is the stack running, and started with the same "
            "config? pass it with --config"
        )
        if settings.auth == "none":
            fix += (
                " (a stack on the secure profile refuses sessions without credentials: "
                "--config deploy/secure.toml)"
            )
        return fix
    if ready:
        return f"the stack is there (ready: {', '.join(sorted(ready))}), but not that service"
    return (
        "a Zenoh session answered, but no service of this stack: check stack.prefix in the "
        "config (--config) against the running stack's"
    )


def unreached(
    what: str,
    settings: ZenohSettings,
    prefix: str,
    principal: str,
    *,
    linked: bool,
    ready: frozenset[str] = frozenset(),
) -> str:
    """One line: what did not answer, where it was looked for, and the likely fix."""
    fix = hint(settings, linked=linked, ready=ready)
    return f"{what} at {describe(settings, prefix, principal)}: {fix}"
