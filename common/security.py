"""Who may be on the bus: the principals and their credential files.

Pure: nothing here opens a session. ``common/zenoh_bus.py`` turns these into Zenoh configuration.

The secure profile runs the stack as a star: the supervisor is a Zenoh *router* that every
service joins as a *client*, authenticated by user name and password (``auth = "password"``)
or by its TLS certificate (``auth = "certificate"``, mutual TLS). Access control runs on the
router, which knows the authenticated name of every link, and every message passes through it.
(In a peer mesh a peer learns the name only of peers that connect to it, not of those it
connects to, so rules by name cannot be enforced there; see docs/security.md.)

Each process has its own principal: each camera process (``camera`` for the first camera,
``camera_<name>`` for each further one, common.settings.camera_service), each detector worker
(``detector``, ``detector_2``, ``detector_<worker_id>`` ...: common.settings.detector_service),
and each other service by its name. What each may put, announce, serve and read is declared by
its service's contract (``services/<name>/contract.py``); stack/access.py builds the router's
rules from them.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

# Every principal the credentials command creates. "estop" is the operator's e-stop tool,
# "observer" may watch (subscribe, query) but publishes nothing: status lines, queries, tests.
SERVICE_PRINCIPALS = (
    "recorder",
    "camera",
    "sim",
    "ros2",
    "detector",
    "controller",
    "metrics",
    "viewer",
)
# The router's principal: the only one whose certificate may serve the TLS listener.
ROUTER_PRINCIPAL = "supervisor"
#: The principals of a one-camera, one-detector stack; :func:`stack_principals` adds one per
#: further camera and names each detector worker.
PRINCIPALS = (ROUTER_PRINCIPAL, *SERVICE_PRINCIPALS, "estop", "observer")
#: The first camera's principal; a further camera's is ``camera_<name>``.
FIRST_CAMERA_PRINCIPAL = "camera"
#: The one detector's principal, and the first worker's of a pool with no ``worker_id``.
DETECTOR_PRINCIPAL = "detector"

AUTH_MODES = ("none", "password", "certificate")


def camera_services(cameras: str | Mapping[str, str]) -> dict[str, str]:
    """``{camera: its service (and principal)}``: ``cameras`` as ``Config.camera_services``
    gives it, the first camera first, or the one camera's name for a one-camera stack."""
    if isinstance(cameras, str):
        return {cameras: FIRST_CAMERA_PRINCIPAL}
    if not cameras:
        raise ValueError("a stack has at least one camera")
    return dict(cameras)


def stack_principals(
    cameras: str | Mapping[str, str], workers: Iterable[str] = (DETECTOR_PRINCIPAL,)
) -> tuple[str, ...]:
    """Every principal of a stack with ``cameras`` (see :func:`camera_services`) and detector
    ``workers`` (``Config.detector_services``; the one ``detector`` by default): PRINCIPALS,
    with each further camera's principal after ``camera`` and the workers in place of
    ``detector``. What ``zstack credentials`` makes."""
    further = [s for s in camera_services(cameras).values() if s != FIRST_CAMERA_PRINCIPAL]
    pool = list(dict.fromkeys(workers))
    if not pool:
        raise ValueError("a stack has at least one detector worker")
    out: list[str] = []
    for p in PRINCIPALS:
        if p == DETECTOR_PRINCIPAL:
            out += pool
        else:
            out.append(p)
            if p == FIRST_CAMERA_PRINCIPAL:
                out += further
    return tuple(out)


def users_file(directory: Path) -> Path:
    """The router's dictionary of ``user:password`` lines."""
    return directory / "users.txt"


def password_file(directory: Path, principal: str) -> Path:
    """One principal's own password, one line."""
    return directory / f"{principal}.password"


def ca_file(directory: Path) -> Path:
    """The private CA's certificate (PEM) that every TLS peer trusts."""
    return directory / "ca.pem"


def ca_key_file(directory: Path) -> Path:
    return directory / "ca.key"


def cert_file(directory: Path, principal: str) -> Path:
    """A principal's certificate (PEM), signed by the private CA, common name = principal."""
    return directory / f"{principal}.pem"


def key_file(directory: Path, principal: str) -> Path:
    return directory / f"{principal}.key"


def viewer_token_file(directory: Path) -> Path:
    """The live view's token (one line): under the secure profile a viewer client must send it
    as the ``token`` query parameter of its WebSocket URL."""
    return directory / "viewer-token"
