"""Who may say what on the bus: principals, their credential files and the access-control rules.

Pure: nothing here opens a session. ``common/bus.py`` turns these into Zenoh configuration.

The secure profile runs the stack as a star: the supervisor is a Zenoh *router* that every
service joins as a *client*, authenticated by user name and password (``auth = "password"``)
or by its TLS certificate (``auth = "certificate"``, mutual TLS). Access control runs on the
router, which knows the authenticated name of every link, and every message passes through it.
(In a peer mesh a peer learns the name only of peers that connect to it, not of those it
connects to, so rules by name cannot be enforced there; see docs/security.md.)

Each process has its own principal and may publish only its own keys: only the controller puts
``cmd_vel``, only the ``estop`` principal the e-stop, only the camera, the simulator, the ROS 2
bridge and the recorder (playing a recording back) frames and scans, only stack services
counters and health tokens. Anything not allowed is denied.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from common.keys import Keys

# Every principal the credentials command creates. "estop" is the operator's e-stop tool,
# "observer" may watch (subscribe, query) but publishes nothing: status lines, queries, tests.
SERVICE_PRINCIPALS = (
    "recorder", "camera", "sim", "ros2", "detector", "controller", "metrics", "viewer"
)
PRINCIPALS = ("supervisor", *SERVICE_PRINCIPALS, "estop", "observer")

AUTH_MODES = ("none", "password", "certificate")

# Zenoh message kinds that only read (or announce interest); every principal may send them.
_READ_MESSAGES = (
    "declare_subscriber",
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
    *_READ_MESSAGES,
)


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


def _principal_keys(keys: Keys, camera: str) -> dict[str, dict[str, tuple[str, ...]]]:
    """What each principal may publish (``put``), announce (``token``) and serve (``serve``)."""

    def service(name: str, *puts: str) -> dict[str, tuple[str, ...]]:
        return {"put": (*puts, keys.counters(name)), "token": (keys.health(name),)}

    return {
        "camera": service("camera", keys.frame(camera)),
        "sim": service("sim", keys.frame(camera), keys.scan(), keys.sim_truth()),
        # The ROS 2 bridge feeds the robot's camera and laser into the stack.
        "ros2": service("ros2", keys.frame(camera), keys.scan()),
        # The recorder listens to everything; playing a recording back puts frames and scans.
        "recorder": service("recorder", keys.frame(camera), keys.scan()),
        "detector": {
            **service("detector", keys.detections(camera)),
            "serve": (keys.detector_info(camera),),
        },
        "controller": service("controller", keys.cmd_vel(), keys.controller_status()),
        "metrics": {**service("metrics"), "serve": (keys.metrics(),)},
        # The live view only reads (and queries the metrics); it announces itself like a service.
        "viewer": service("viewer"),
        "estop": {"put": (keys.estop(),)},
        "supervisor": {},  # its own session lives inside the router: no rule applies to it
        "observer": {},
    }


def access_control(
    keys: Keys, camera: str, auth: str, principals: tuple[str, ...] = PRINCIPALS
) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for the router: deny by default, then allow each
    principal its own keys on ingress, reading for everyone, and everything on egress (the
    router delivers only what it accepted)."""
    if auth not in AUTH_MODES[1:]:
        raise ValueError(f"access control needs an authenticated mode, got {auth!r}")
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
            "id": "read",
            "messages": list(_READ_MESSAGES),
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": ["**"],
        },
    ]
    subjects: list[dict[str, Any]] = [{"id": "everyone", match: list(principals)}]
    policies: list[dict[str, Any]] = [{"rules": ["egress", "read"], "subjects": ["everyone"]}]
    kinds = {"put": ["put"], "token": ["liveliness_token"], "serve": ["declare_queryable", "reply"]}
    for principal, allowed in _principal_keys(keys, camera).items():
        if principal not in principals:
            continue
        subjects.append({"id": principal, match: [principal]})
        ids = []
        for kind, key_exprs in allowed.items():
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


def may_put(keys: Keys, camera: str, principal: str) -> tuple[str, ...]:
    """The keys ``principal`` may put on (documentation and tests read the same table)."""
    return _principal_keys(keys, camera).get(principal, {}).get("put", ())


def viewer_token_file(directory: Path) -> Path:
    """The live view's token (one line): under the secure profile a viewer client must send it
    as the ``token`` query parameter of its WebSocket URL."""
    return directory / "viewer-token"
