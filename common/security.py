"""Who may say what on the bus: principals, their credential files and the access-control rules.

Pure: nothing here opens a session. ``common/zenoh_bus.py`` turns these into Zenoh configuration.

The secure profile runs the stack as a star: the supervisor is a Zenoh *router* that every
service joins as a *client*, authenticated by user name and password (``auth = "password"``)
or by its TLS certificate (``auth = "certificate"``, mutual TLS). Access control runs on the
router, which knows the authenticated name of every link, and every message passes through it.
(In a peer mesh a peer learns the name only of peers that connect to it, not of those it
connects to, so rules by name cannot be enforced there; see docs/security.md.)

Each process has its own principal and may publish only its own keys: only the controller puts
``cmd_vel``, only the ``estop`` principal the e-stop, only the cameras, the simulator and the
ROS 2 bridge frames and scans, only stack services counters and health tokens. Each camera
process is a principal of its own (``camera`` for the first camera, ``camera_<name>`` for each
further one, common.settings.camera_service) and may put only its own camera's frames; the
detector puts every camera's detections and no frame. Each detector worker of a pool is a
principal of its own too (its name, ``detector``, ``detector_2``, ``detector_<worker_id>`` ...:
common.settings.detector_service): any worker may serve any camera, so each may put every
camera's detections, but it announces only its own health and pool tokens. The recorder
(playing a recording back) may put frames and scans only on a stack that runs no live sensor
(no camera, simulator or ROS 2 bridge): a replay must never reach a live robot's keys.

Each principal may also subscribe only to what it reads: the camera frames only to the
detector, the live view, the recorder and the ROS 2 bridge. Zenoh allows a subscription only
when its key expression lies within an allowed one, so a wider one (``<prefix>/**``) is denied
whole, not trimmed. Queries and liveliness (health tokens) stay open to every principal.
Anything not allowed is denied.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from common.keys import Keys

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

#: The services that feed a live robot's sensors into the stack: while one of them runs, no
#: recording may be played onto its keys. Every further camera's ``camera_<name>`` too
#: (:func:`running_sensors`).
LIVE_SENSORS = frozenset({"camera", "sim", "ros2"})

# Zenoh message kinds that only ask (or announce interest); every principal may send them.
_ASK_MESSAGES = (
    "query",
    "declare_liveliness_subscriber",
    "liveliness_query",
)
_ALL_MESSAGES = (
    "put",
    "delete",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "declare_subscriber",
    *_ASK_MESSAGES,
)


def running_sensors(services: Iterable[str]) -> list[str]:
    """Those of ``services`` that feed a live robot's sensors (any camera, the simulator, the
    ROS 2 bridge), sorted."""
    return sorted(
        s for s in set(services) if s in LIVE_SENSORS or s.startswith(f"{FIRST_CAMERA_PRINCIPAL}_")
    )


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


def _principal_keys(
    keys: Keys,
    cameras: str | Mapping[str, str],
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> dict[str, dict[str, tuple[str, ...]]]:
    """What each principal may publish (``put``), announce (``token``), serve (``serve``) and
    subscribe to (``read``). ``cameras``: see :func:`camera_services`. ``live_sensors``: the
    stack runs a camera, the simulator or the ROS 2 bridge, so the recorder may not play frames
    or scans onto it. ``workers``: the detector workers' names (``Config.detector_services``),
    each a principal."""

    def service(name: str, *puts: str, read: tuple[str, ...] = ()) -> dict[str, tuple[str, ...]]:
        out = {"put": (*puts, keys.counters(name)), "token": (keys.health(name),)}
        return {**out, "read": read} if read else out

    services = camera_services(cameras)
    # Puts name each configured camera's key: nobody may put on a camera the stack does not
    # have. Reads and the detector's info take the wildcard, so that one subscription (or
    # queryable) for every camera is accepted as well as one per camera; nobody can put on
    # an unconfigured camera's key, so the wildcard reads nothing more.
    frames = tuple(keys.frame(c) for c in services)
    all_frames = keys.all_frames()
    detections = keys.all_detections()
    # Everything but the camera's pictures: what status lines, tests and tools watch.
    watching = (
        detections, keys.scan(), keys.cmd_vel(), keys.controller_status(), keys.estop(),
        keys.sim_truth(), keys.all_counters(),
    )  # fmt: skip
    replay = () if live_sensors else (*frames, keys.scan())
    # Each camera process puts its own camera's frames only, and reads nothing.
    camera_rules = {name: service(name, keys.frame(c)) for c, name in services.items()}
    # Each detector worker reads frames and puts detections, never frames: every camera's, as
    # any worker may come to serve any camera (services/detector/pool.py). Its tokens are its
    # own only: its health, its pool membership and its serving tokens under its own name, so
    # that no worker can pose as another, or as many, and skew the assignment or its audit.
    worker_rules = {
        w: {
            **service(w, *(keys.detections(c) for c in services), read=(all_frames,)),
            "token": (keys.health(w), keys.pool_member(w), keys.pool_serving_of(w)),
            "serve": (keys.all_detector_info(),),
        }
        for w in dict.fromkeys(workers)
    }
    return {
        **camera_rules,
        **worker_rules,
        # The simulator renders every camera from one world.
        "sim": service("sim", *frames, keys.scan(), keys.sim_truth(), read=(keys.cmd_vel(),)),
        # The ROS 2 bridge feeds the robot's cameras and laser into the stack, and the stack's
        # detections and commands out to the robot (held at zero by the controller's status).
        "ros2": service(
            "ros2",
            *frames,
            keys.scan(),
            read=(all_frames, detections, keys.cmd_vel(), keys.controller_status()),
        ),
        # The recorder listens to everything; playing a recording back puts frames and scans,
        # on a stack with no live sensor only.
        "recorder": service("recorder", *replay, read=(f"{keys.prefix}/**",)),
        "controller": service(
            "controller",
            keys.cmd_vel(),
            keys.controller_status(),
            read=(detections, keys.scan(), keys.estop()),
        ),
        "metrics": {
            **service("metrics", read=(detections, keys.cmd_vel(), keys.all_counters())),
            "serve": (keys.metrics(),),
        },
        # The live view reads what it shows (and queries the metrics); it announces itself.
        "viewer": service(
            "viewer",
            read=(
                all_frames,
                detections,
                keys.scan(),
                keys.cmd_vel(),
                keys.controller_status(),
                keys.sim_truth(),
            ),
        ),
        "estop": {"put": (keys.estop(),), "read": (keys.controller_status(),)},
        "supervisor": {},  # its own session lives inside the router: no rule applies to it
        "observer": {"read": watching},
    }


def access_control(
    keys: Keys,
    cameras: str | Mapping[str, str],
    auth: str,
    principals: tuple[str, ...] | None = None,
    *,
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for the router: deny by default, then allow each
    principal its own keys on ingress (puts, tokens, queryables, subscriptions), queries and
    liveliness for everyone, and everything on egress (the router delivers only what it
    accepted, and only to subscriptions it accepted). ``cameras``: see
    :func:`camera_services`; ``principals`` (default: :func:`stack_principals`) limits the
    rules to those named; ``workers``: the detector workers' names (``Config.detector_services``),
    each a principal."""
    if auth not in AUTH_MODES[1:]:
        raise ValueError(f"access control needs an authenticated mode, got {auth!r}")
    workers = tuple(workers)
    if principals is None:
        principals = stack_principals(cameras, workers)
    match = "usernames" if auth == "password" else "cert_common_names"
    rules: list[dict[str, Any]] = [
        {
            "id": "egress",
            "messages": list(_ALL_MESSAGES),
            "flows": ["egress"],
            "permission": "allow",
            "key_exprs": ["**"],
        },
        {
            "id": "ask",
            "messages": list(_ASK_MESSAGES),
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": ["**"],
        },
    ]
    subjects: list[dict[str, Any]] = [{"id": "everyone", match: list(principals)}]
    policies: list[dict[str, Any]] = [{"rules": ["egress", "ask"], "subjects": ["everyone"]}]
    kinds = {
        "put": ["put"],
        "token": ["liveliness_token"],
        "serve": ["declare_queryable", "reply"],
        "read": ["declare_subscriber"],
    }
    allowed_keys = _principal_keys(keys, cameras, live_sensors, workers)
    for principal, allowed in allowed_keys.items():
        if principal not in principals:
            continue
        subjects.append({"id": principal, match: [principal]})
        ids = []
        for kind, key_exprs in allowed.items():
            if not key_exprs:
                continue
            rule_id = f"{principal}_{kind}"
            rules.append(
                {
                    "id": rule_id,
                    "messages": kinds[kind],
                    "flows": ["ingress"],
                    "permission": "allow",
                    "key_exprs": list(key_exprs),
                }
            )
            ids.append(rule_id)
        if ids:
            policies.append({"rules": ids, "subjects": [principal]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def may_put(
    keys: Keys,
    cameras: str | Mapping[str, str],
    principal: str,
    *,
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The keys ``principal`` may put on (documentation and tests read the same table)."""
    table = _principal_keys(keys, cameras, live_sensors, workers)
    return table.get(principal, {}).get("put", ())


def congestion_overwritten(
    keys: Keys,
    cameras: str | Mapping[str, str],
    *,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The keys on which the router puts congestion control DROP on every sample it takes in,
    whatever its publisher asked for: every key any principal may put on (a replay's too),
    but the e-stop. A client's BLOCK there would make the router wait on a full link (a frozen
    listener's) and hold up everyone's traffic behind it (docs/security.md, "QoS by role")."""
    puts: dict[str, None] = {}
    for live in (True, False):
        for allowed in _principal_keys(keys, cameras, live, workers).values():
            puts.update(dict.fromkeys(allowed.get("put", ())))
    return tuple(k for k in puts if k != keys.estop())


def may_announce(
    keys: Keys,
    cameras: str | Mapping[str, str],
    principal: str,
    *,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The liveliness tokens ``principal`` may declare (its health, a worker's pool and serving
    tokens)."""
    return _principal_keys(keys, cameras, workers=workers).get(principal, {}).get("token", ())


def may_read(keys: Keys, cameras: str | Mapping[str, str], principal: str) -> tuple[str, ...]:
    """The key expressions ``principal`` may subscribe to (within which any subscription)."""
    return _principal_keys(keys, cameras).get(principal, {}).get("read", ())


def viewer_token_file(directory: Path) -> Path:
    """The live view's token (one line): under the secure profile a viewer client must send it
    as the ``token`` query parameter of its WebSocket URL."""
    return directory / "viewer-token"
