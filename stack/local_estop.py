"""``zstack estop engage``'s local road: the engage handed to the controller on this host
through its socket (common/estop_local.py), before Zenoh is even imported."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from common.errors import ConfigError
from common.estop_local import engage_locally, socket_path
from stack.config_read import load_estop_file_path


def engage_here(config: str | Path | None, reason: str) -> str:
    """Hand an engage to the controller of ``config`` if it runs on this host; "" when it
    took it, else why not (the Zenoh road, which always follows, reports a bad config)."""
    try:
        path = load_estop_file_path(config)
    except ConfigError as exc:
        return str(exc)
    return engage_locally(socket_path(path), reason)


def option(words: Sequence[str], name: str) -> str | None:
    """The value of ``--name VALUE`` or ``--name=VALUE`` in ``words`` (the last one), read
    before the command's own parser runs."""
    value = None
    for i, word in enumerate(words):
        if word == name and i + 1 < len(words):
            value = words[i + 1]
        elif word.startswith(name + "="):
            value = word[len(name) + 1 :]
    return value
