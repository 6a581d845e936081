"""Settings every service shares: how a process joins the bus (``[zenoh]``), the stack's names
(``[stack]``), and the names of the services (common/service_list.py's one list), their
processes and principals.

Each service's own settings table is declared in its contract (``services/<name>/contract.py``);
the whole ``Config`` is assembled from them in stack/config.py, and read from the TOML file with
its environment overrides in stack/config_file.py. Each dataclass validates itself and raises
ConfigError with one line for an out-of-range value.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from common.errors import ConfigError
from common.security import AUTH_MODES, qualified
from common.service_list import SERVICES as SERVICES  # runnable by the supervisor, in order
from common.setting_checks import Length, Range, check_bounds, check_lengths

REPO_ROOT = Path(__file__).resolve().parent.parent
#: The most cameras one stack serves (one detector process serves them all).
MAX_CAMERAS = 16
_CAMERA_NAME = re.compile(r"[a-z0-9][a-z0-9_]{0,31}")


def check_camera_name(name: str) -> None:
    """A camera name is a key chunk, a process name and a file name: ``[a-z0-9_]``, 1..32."""
    if not _CAMERA_NAME.fullmatch(name):
        raise ConfigError(
            f"camera name {name!r} must be 1..32 of a-z, 0-9 and _ (starting with a letter or "
            "digit): it names keys, processes and files"
        )


def camera_service(first: str, camera: str) -> str:
    """The service (process, health token, counters, principal) of ``camera``: ``camera`` for
    the first camera (``stack.camera``), as a one-camera stack has always named it, and
    ``camera_<name>`` for each further one."""
    return "camera" if camera == first else f"camera_{camera}"


def detector_service(n: int, worker_id: str = "") -> str:
    """The one name of this host's ``n``-th detector worker (from 1): its service, process,
    health token, counters key, pool id and principal. ``detector``, ``detector_2`` ... with
    no ``detector.worker_id`` (the first as a one-detector stack has always named it);
    ``detector_<id>``, ``detector_<id>_2`` ... with one, so that workers on several hosts,
    each host with its own id, never share a name."""
    base = f"detector_{worker_id}" if worker_id else "detector"
    return base if n == 1 else f"{base}_{n}"


#: Any detector worker's name, on any host (``detector_service``'s names): what the metrics
#: service believes counters from without knowing the other hosts' configs.
_PREFIX = re.compile(r"[A-Za-z0-9_.\-]{1,64}(/[A-Za-z0-9_.\-]{1,64})*")
_DETECTOR_SERVICE = re.compile(r"detector(_[a-z0-9_]{1,40})?")


def is_detector_service(name: str) -> bool:
    """Whether ``name`` can be a detector worker's name (``detector``, ``detector_<chunk>``)."""
    return _DETECTOR_SERVICE.fullmatch(name) is not None


def principal_name(prefix: str, role: str, pool_prefix: str = "") -> str:
    """The name ``role`` authenticates as on the stack of ``prefix`` (common/security.py): a
    detector worker's is its pool's (``pool_prefix``, or the stack's prefix), since one worker
    may serve several robots; every other role's its robot's, ``<prefix>/<role>``."""
    scope = (pool_prefix or prefix) if is_detector_service(role) else prefix
    return qualified(scope, role)


def principal_names(prefix: str, pool_prefix: str = "") -> Callable[[str], str]:
    """:func:`principal_name` for each role of the stack of ``prefix``."""
    return lambda role: principal_name(prefix, role, pool_prefix)


def service_package(service: str) -> str:
    """The package a service runs from, ``services.<package>``: ``camera`` for every camera's
    service (``camera``, ``camera_<name>``), ``detector`` for every detector worker's
    (``detector``, ``detector_<n>``), the service's own name otherwise."""
    for package in ("camera", "detector"):
        if service.startswith(f"{package}_"):
            return package
    return service


DEFAULT_CONFIG = REPO_ROOT / "deploy" / "stack.toml"
# zenoh.max_payload_bytes: a counters message must fit; Zenoh refuses to receive above 1 GiB.
MIN_PAYLOAD_LIMIT = 64 * 1024
MAX_PAYLOAD_LIMIT = 1 << 30


@dataclass(frozen=True, slots=True, kw_only=True)
class ZenohSettings:
    """How every process joins the bus.

    The supervisor listens on ``endpoint``; services connect to it and to ``connect`` (other
    hosts), and listen on ``listen`` (port 0: any free port) so that peers mesh directly.
    Multicast scouting is off by default: robots share networks, and tests must stay private.

    ``mode = "client"`` makes the supervisor a Zenoh router that every service joins, so that
    all traffic passes through it. ``auth`` ("none", "password" or "certificate") turns on
    authentication and access control there, with the credentials that
    ``zstack credentials`` writes to ``credentials_dir`` (relative to the repo root);
    it needs client mode. An endpoint ``tls/<host>:<port>`` encrypts the links with the same
    credentials; "certificate" needs one (mutual TLS). See docs/security.md.

    Routers linked across hosts (``connect`` on a host whose supervisor is a router): each
    router admits the other's traffic as the principal of the router's certificate
    (``<its stack.prefix>/supervisor``, one of ``linked_routers``), and lets it do what
    ``remote_principals`` may do together: the
    principals the other hosts run (``detector_a`` on the robot; the robot's cameras, worker,
    controller, metrics ... on the GPU box). Empty: a linked router may only ask (queries,
    liveliness). Under access control that needs ``auth = "certificate"``: with passwords
    the router that dials cannot tell which router answered, and its rules deny it all.

    ``linked_routers``: the ``stack.prefix`` of each other host's router this router links
    with (dials or is dialled by). Each router authenticates as ``<stack.prefix>/supervisor``
    (its own certificate), and only those named here get a linked router's rights (empty: this
    stack's own prefix, two hosts of one robot): robot 1's router key opens nothing on robot
    2's router, whose rules name neither it nor robot 1's other principals.

    ``max_payload_bytes`` is the largest payload a service sends; a larger one is counted
    (``payload_too_large``) and not sent, because Zenoh silently loses big payloads under
    congestion control DROP (64 MiB on loopback; 48 MiB still arrived). 32 MiB leaves a
    margin for a loaded host and fits a raw 3840x2160 bgr8 frame (24 MiB).
    """

    mode: str = "peer"
    # Not Zenoh's usual 7447: on a ROS 2 robot rmw_zenohd holds that one.
    endpoint: str = "tcp/127.0.0.1:7448"
    connect: Annotated[tuple[str, ...], Length(0, 16)] = ()
    listen: Annotated[tuple[str, ...], Length(0, 16)] = ("tcp/127.0.0.1:0",)
    multicast_scouting: bool = False
    auth: str = "none"
    credentials_dir: str = "secrets"
    max_payload_bytes: Annotated[int, Range(MIN_PAYLOAD_LIMIT, MAX_PAYLOAD_LIMIT)] = 32 << 20
    remote_principals: Annotated[tuple[str, ...], Length(0, 64)] = ()
    linked_routers: Annotated[tuple[str, ...], Length(0, 16)] = ()

    def __post_init__(self) -> None:
        check_bounds(self, "zenoh", ZenohSettings)
        check_lengths(self, "zenoh", ZenohSettings)
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"zenoh.mode must be 'peer' or 'client', got {self.mode!r}")
        for ep in (self.endpoint, *self.connect, *self.listen):
            if "/" not in ep:
                raise ConfigError(f"zenoh endpoint {ep!r} must look like tcp/<host>:<port>")
        if self.auth not in AUTH_MODES:
            modes = ", ".join(AUTH_MODES)
            raise ConfigError(f"zenoh.auth must be one of {modes}, got {self.auth!r}")
        if self.auth != "none" and self.mode != "client":
            raise ConfigError(
                'zenoh.auth needs zenoh.mode = "client": access control runs on the supervisor\'s '
                "router, which must see every message"
            )
        if self.auth == "certificate" and not self.uses_tls:
            raise ConfigError('zenoh.auth = "certificate" needs a tls/<host>:<port> endpoint')
        if self.auth == "password" and self.connect:
            raise ConfigError(
                'zenoh.connect (routers linked across hosts) needs zenoh.auth = "certificate" '
                "under access control: with passwords the router that dials cannot tell which "
                "router answered, so its rules would refuse all of that router's traffic "
                '(docs/security.md, "Two hosts, secured")'
            )
        if not self.credentials_dir:
            raise ConfigError("zenoh.credentials_dir must not be empty")
        for prefix in self.linked_routers:
            if not _PREFIX.fullmatch(prefix) or any(c in (".", "..") for c in prefix.split("/")):
                raise ConfigError(
                    f"zenoh.linked_routers names {prefix!r}: write the stack.prefix of a "
                    "linked host's router ('/'-separated words of letters, digits, '_', '-', "
                    "'.'; its router is <prefix>/supervisor)"
                )
        if len(set(self.linked_routers)) != len(self.linked_routers):
            raise ConfigError(f"zenoh.linked_routers names one twice: {list(self.linked_routers)}")

    @property
    def uses_tls(self) -> bool:
        return any(ep.startswith("tls/") for ep in (self.endpoint, *self.connect))

    @property
    def credentials_path(self) -> Path:
        path = Path(self.credentials_dir).expanduser()
        return path if path.is_absolute() else REPO_ROOT / path


@dataclass(frozen=True, slots=True, kw_only=True)
class StackSettings:
    """Names shared by all services (the key prefix and the camera they work on), and how far
    ahead of the receiver's clock a stamp may be before it counts as from the future
    (``clock_tolerance_s``: the clock offset allowed between hosts; see docs/security.md)."""

    prefix: str = "stack"
    camera: str = "front"
    clock_tolerance_s: Annotated[float, Range(0, 5)] = 0.1

    def __post_init__(self) -> None:
        check_bounds(self, "stack", StackSettings)
