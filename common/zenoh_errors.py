"""Zenoh's errors in words a user can act on.

Zenoh's messages carry the Rust source location of every layer they passed (``... at
/root/.cargo/git/checkouts/zenoh-.../tcp.rs:61.]``): noise on a user's terminal. The text is
kept, the locations go, and a port that is taken gets the likely culprit and the fix.
"""

from __future__ import annotations

import re

# " at /path/to/file.rs:123." (a location ends a layer's message, before "]" or the end).
_RUST_LOCATION = re.compile(r"\s+at\s+\S+\.rs:\d+\.?")
_PORT_TAKEN = re.compile(r"(?:tcp|udp|tls|quic)/[^\s:]+:(\d+)|\S+:(\d+): Address already in use")

#: Who usually holds a port on a robot: what a user should look for.
KNOWN_PORTS = {
    7447: "rmw_zenohd, the ROS 2 Zenoh router, listens there by default",
    8765: "foxglove_bridge listens there by default",
}


def clean(message: str) -> str:
    """``message`` without Rust source locations and the brackets they leave."""
    text = _RUST_LOCATION.sub("", message)
    text = text.replace("[", "").replace("]", "")
    return re.sub(r"\s{2,}", " ", text).strip().rstrip(".")


def port_hint(message: str) -> str:
    """For "Address already in use": which port, who may hold it and what to do; else ""."""
    if "Address already in use" not in message:
        return ""
    found = _PORT_TAKEN.search(message)
    port = int(next(g for g in found.groups() if g)) if found else None
    if port is None:
        return "; the port is taken: choose another in zenoh.endpoint"
    holder = KNOWN_PORTS.get(port, "another program")
    return (
        f"; port {port} is taken ({holder}): set zenoh.endpoint to a free port, or find the "
        f"holder with `ss -ltnp 'sport = :{port}'`"
    )


def explain(message: str) -> str:
    """The cleaned message and, where it applies, the hint."""
    return clean(message) + port_hint(message)
