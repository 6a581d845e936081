"""Zenoh's errors in words a user can act on.

Zenoh's messages carry the Rust source location of every layer they passed (``... at
/root/.cargo/git/checkouts/zenoh-.../tcp.rs:61.]``): noise on a user's terminal. The text is
kept, the locations go, and a port that is taken gets its holder (common/ports.py) and the fix.
"""

from __future__ import annotations

import re
from pathlib import Path

from common.ports import PROC, holder_words

# " at /path/to/file.rs:123." (a location ends a layer's message, before "]" or the end).
_RUST_LOCATION = re.compile(r"\s+at\s+\S+\.rs:\d+\.?")
_PORT_TAKEN = re.compile(r"(?:tcp|udp|tls|quic)/[^\s:]+:(\d+)|\S+:(\d+): Address already in use")


def clean(message: str) -> str:
    """``message`` without Rust source locations and the brackets they leave."""
    text = _RUST_LOCATION.sub("", message)
    text = text.replace("[", "").replace("]", "")
    return re.sub(r"\s{2,}", " ", text).strip().rstrip(".")


def port_hint(message: str, proc: Path = PROC) -> str:
    """For "Address already in use": which port, who may hold it and what to do; else ""."""
    if "Address already in use" not in message:
        return ""
    found = _PORT_TAKEN.search(message)
    port = int(next(g for g in found.groups() if g)) if found else None
    if port is None:
        return "; the port is taken: choose another in zenoh.endpoint"
    return f"; port {port} is taken ({holder_words(port, proc)}): set zenoh.endpoint to a free port"


def explain(message: str) -> str:
    """The cleaned message and, where it applies, the hint."""
    return clean(message) + port_hint(message)
