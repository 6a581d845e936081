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

Those are *roles*. The name a process authenticates as (its certificate's common name, its
password's user name) is its role qualified by whose it is (:func:`qualified`,
common.settings.principal_name): ``<stack.prefix>/<role>`` for a robot's own processes and
tools (``stack/controller``, ``site/robot1/estop``), ``<pool>/<worker>`` for a detector worker
(the pool's prefix, ``detector.pool_prefix`` or the stack's: one worker may serve several
robots), and each router's ``<stack.prefix>/supervisor`` (its robot's, or its host's stack:
robot 1's router is ``site/robot1/supervisor``). So one site CA can sign every robot's
principals while each robot's router admits only its own robot's (and its pool's workers, and
the routers it is configured to link with, ``zenoh.linked_routers``): robot 1's ``estop`` is
``site/robot1/estop``, and its router ``site/robot1/supervisor``, names robot 2's rules never
match. Each principal's files live at its name under the credentials folder
(``secrets/site/robot1/estop.password``): one subfolder per robot, easy to copy.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from common.errors import ConfigError
from common.service_list import SERVICES

# Every principal the credentials command creates: each service's (its name, in the one list,
# common/service_list.py), and the tools'. "estop" is the operator's e-stop tool, "observer"
# may watch (subscribe, query) but publishes nothing: status lines, queries, tests.
SERVICE_PRINCIPALS = SERVICES
# The router's role: the only one whose certificates (one per stack, ``<prefix>/supervisor``)
# may serve the TLS listener.
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


def qualified(scope: str, role: str) -> str:
    """The name ``role`` authenticates as, within ``scope`` (a robot's prefix, or its pool's
    for a detector worker): ``<scope>/<role>``, the router's (``<prefix>/supervisor``) too."""
    return f"{scope}/{role}"


def is_router(principal: str) -> bool:
    """Whether ``principal`` (a name or a role) is a router's: ``supervisor`` or
    ``<prefix>/supervisor``."""
    return role_of(principal) == ROUTER_PRINCIPAL


def role_of(principal: str) -> str:
    """The role of a principal's name: ``controller`` for ``site/robot1/controller``."""
    return principal.rsplit("/", 1)[-1]


def _at(directory: Path, principal: str, suffix: str) -> Path:
    """``principal``'s file: its name is its path under ``directory`` (``site/robot1/estop``:
    ``site/robot1/estop<suffix>``). ConfigError, one line, for a name that could leave the
    folder (an empty, ``.`` or ``..`` chunk)."""
    chunks = principal.split("/")
    if any(c in ("", ".", "..") for c in chunks):
        raise ConfigError(
            f"principal {principal!r} cannot name a credentials file: a stack.prefix or "
            "detector.pool_prefix with an empty, '.' or '..' chunk"
        )
    return directory.joinpath(*chunks[:-1], f"{chunks[-1]}{suffix}")


def made_by_role(directory: Path, principal: str) -> bool:
    """Whether ``directory`` holds ``principal``'s files under its role alone
    (``controller.pem`` for ``stack/controller``), as versions before per-robot principals
    made them, and not under its name: credentials to make again (:func:`remake_by_role`)."""
    role = role_of(principal)
    if role == principal:
        return False
    made = (password_file, cert_file, key_file)
    return not any(f(directory, principal).exists() for f in made) and any(
        f(directory, role).exists() for f in made
    )


def remake_by_role(directory: Path, config_path: str = "") -> str:
    """The one line that says credentials named by role alone must be made again."""
    return (
        f"the credentials in {directory} were made by an older version that named principals "
        "by role alone (controller, estop ...: one robot's then worked on every robot's "
        "router); principals are now per robot (<stack.prefix>/<role>): make them again with "
        f"`zstack credentials --config {config_path or 'FILE'} --force` (docs/security.md)"
    )


def users_file(directory: Path) -> Path:
    """The router's dictionary of ``user:password`` lines."""
    return directory / "users.txt"


def password_file(directory: Path, principal: str) -> Path:
    """One principal's own password, one line."""
    return _at(directory, principal, ".password")


def ca_file(directory: Path) -> Path:
    """The private CA's certificate (PEM) that every TLS peer trusts."""
    return directory / "ca.pem"


def ca_key_file(directory: Path) -> Path:
    return directory / "ca.key"


def cert_file(directory: Path, principal: str) -> Path:
    """A principal's certificate (PEM), signed by the private CA, common name = its name."""
    return _at(directory, principal, ".pem")


def key_file(directory: Path, principal: str) -> Path:
    return _at(directory, principal, ".key")


def viewer_token_file(directory: Path) -> Path:
    """The live view's token (one line): under the secure profile a viewer client must send it
    as the ``token`` query parameter of its WebSocket URL."""
    return directory / "viewer-token"
