"""The one place where a Zenoh configuration is built and a session opened.

Only service I/O modules (``services/*/service.py``), the supervisor and the command-line
clients import this module; the logic modules never touch the bus.
"""

from __future__ import annotations

import json
import logging

import zenoh

from common.errors import ConfigError
from common.settings import ZenohSettings

log = logging.getLogger(__name__)


def zenoh_config(settings: ZenohSettings, *, hub: bool = False) -> zenoh.Config:
    """Build the Zenoh config every process uses.

    ``hub`` is for the supervisor: it listens on ``settings.endpoint`` so that the services,
    which connect to that endpoint, find each other there and then mesh directly.
    """
    if hub:
        listen = [settings.endpoint, *settings.listen]
        listen = [ep for ep in listen if not ep.endswith(":0")] or [settings.endpoint]
        connect = list(settings.connect)
    else:
        listen = list(settings.listen)
        connect = [settings.endpoint, *settings.connect]
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(settings.mode))
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    conf.insert_json5("connect/endpoints", json.dumps(connect))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(settings.multicast_scouting))
    return conf


def open_session(settings: ZenohSettings, *, hub: bool = False) -> zenoh.Session:
    """Open a session, translating Zenoh's errors (a port in use, a bad locator) to ConfigError."""
    try:
        return zenoh.open(zenoh_config(settings, hub=hub))
    except zenoh.ZError as exc:
        where = settings.endpoint if hub else ", ".join(settings.listen)
        raise ConfigError(f"cannot open a Zenoh session on {where}: {exc}") from exc
