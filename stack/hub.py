"""The supervisor's hub: the Zenoh router every service joins in client mode, with the access
rules of this stack (stack/access.py) and congestion control overwritten to DROP on every key but
the e-stop (common/zenoh_bus.py, "QoS by role")."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import zenoh

from common.errors import ConfigError
from common.keys import Keys
from common.security import (
    ROUTER_PRINCIPAL,
    ca_file,
    cert_file,
    key_file,
    made_by_role,
    remake_by_role,
    users_file,
)
from common.settings import is_detector_service
from common.zenoh_bus import HUB_PRINCIPAL, open_configured, readable, zenoh_config
from stack.access import access_control
from stack.access_table import congestion_overwritten, running_sensors
from stack.config import Config
from stack.principals import running_principals, service_principals


def hub_access(config: Config) -> dict[str, Any]:
    """The supervisor's access-control rules for this stack's keys ({} without auth)."""
    z = config.zenoh
    if z.auth == "none":
        return {}
    live = bool(running_sensors(config.supervisor.services))
    keys = Keys(config.stack.prefix)
    try:
        return access_control(
            keys,
            config.camera_services,
            z.auth,
            live_sensors=live,
            workers=config.detector_services,
            prefixes=config.detector.prefixes,
            remote=z.remote_principals,
            pool_prefix=config.detector.pool_prefix,
            linked=z.linked_routers,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc


def hub_drop_keys(config: Config) -> tuple[str, ...]:
    """The keys on which the supervisor's router overwrites congestion control to DROP: every
    key of the stack but the e-stop (stack.access_table.congestion_overwritten)."""
    keys = Keys(config.stack.prefix)
    remote = [p for p in config.zenoh.remote_principals if is_detector_service(p)]
    workers = (*config.detector_services, *remote)
    return congestion_overwritten(
        keys, config.camera_services, workers=workers, prefixes=config.detector.prefixes
    )


def check_credentials(config: Config) -> None:
    """The credentials must serve every principal this stack runs, or a process would be
    refused after the others started: with passwords the router's dictionary must name each
    principal of stack.principals.running_principals (the router, each process of
    ``supervisor.services``, the tools), by its name (``<stack.prefix>/<role>``,
    common/security.py); with certificates each process the supervisor starts needs its
    certificate and key (the tools' files may live on another host). ConfigError, one line,
    naming the command that makes them again for this config; a folder made by an older
    version (principals named by role alone) says so."""
    z = config.zenoh
    creds = z.credentials_path
    services, cameras, workers = (
        config.supervisor.services, config.camera_services, config.detector_services
    )  # fmt: skip
    again = f"`zstack credentials --config {config.path or 'FILE'} --force`"
    if z.auth == "password":
        path = Path(readable(users_file(creds), "user dictionary"))
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"cannot read {path}: {exc}") from exc
        known = {line.split(":", 1)[0] for line in text.splitlines()}
        needed = [config.principal(p) for p in running_principals(services, cameras, workers)]
        missing = [p for p in needed if p not in known]
        if missing and not any("/" in p for p in known):  # every user named by role alone
            raise ConfigError(remake_by_role(creds, config.path))
    elif z.auth == "certificate" and ca_file(creds).is_file():  # no CA: the router says so
        needed = [
            config.principal(p)
            for p in (ROUTER_PRINCIPAL, *service_principals(services, cameras, workers))
        ]
        if any(made_by_role(creds, p) for p in needed):
            raise ConfigError(remake_by_role(creds, config.path))
        files = {p: (cert_file(creds, p), key_file(creds, p)) for p in needed}
        missing = [p for p, paths in files.items() if not all(f.is_file() for f in paths)]
    else:
        return
    if missing:
        raise ConfigError(
            f"the credentials in {creds} have no principal {', '.join(missing)} (made for a "
            "config that runs fewer services, cameras or detector workers, or for another "
            f"robot's stack.prefix?): make them again with {again} (docs/security.md)"
        )


def open_hub(config: Config) -> zenoh.Session:
    """The supervisor's session: the endpoint every service joins, enforcing access control."""
    check_credentials(config)
    router = config.principal(HUB_PRINCIPAL)  # <stack.prefix>/supervisor: this stack's router
    conf = zenoh_config(
        config.zenoh, router, access=hub_access(config), drop_keys=hub_drop_keys(config)
    )
    return open_configured(conf, config.zenoh, config.zenoh.endpoint, router)
