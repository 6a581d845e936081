"""Who may say what on the bus: the router's access-control rules, built from what each
service's contract (``services/<name>/contract.py``) declares it puts, announces, serves and
reads. Pure: nothing here opens a session; stack/hub.py hands the rules to the router.

Each process has its own principal (common/security.py) and may publish only its own keys:
only the controller puts ``cmd_vel``, only the ``estop`` principal the e-stop, only the
cameras, the simulator and the ROS 2 bridge frames and scans, only stack services counters and
health tokens. Each camera process may put only its own camera's frames and announce only its
own camera (the simulator, the ROS 2 bridge and a replay: each camera whose frames they may
put); the detector puts every camera's detections and no frame. Each detector worker of a pool
may put every camera's detections (any worker may serve any camera), but announces only its own
health and pool tokens. The recorder (playing a recording back) may put frames and scans only on
a stack that runs no live sensor (no camera, simulator or ROS 2 bridge): a replay must never
reach a live robot's keys.

Each principal may also subscribe only to what it reads: the camera frames only to the
detector, the live view, the recorder and the ROS 2 bridge. Zenoh allows a subscription only
when its key expression lies within an allowed one, so a wider one (``<prefix>/**``) is denied
whole, not trimmed. Queries and liveliness subscriptions are open to every principal, within
the stack's prefix and the robot prefixes its detector workers serve: nothing of another
robot's on the same (or a linked) router. Anything not allowed is denied.

The rules name each principal as it authenticates, its role qualified by whose it is
(common/security.py): ``<prefix>/controller`` for this robot's, ``<pool>/detector_gpu`` for a
pool's worker. One site CA signs every robot's principals, and another robot's (its
``controller``, its ``estop``) matches no subject here: denied everything.

Routers linked across hosts admit each other by the router's principal, per stack
(``<stack.prefix>/supervisor``, by its certificate): a router lets the routers of
``zenoh.linked_routers`` (their stacks' prefixes; none named: its own stack's, two hosts of one
robot) do what the principals the other hosts run (``zenoh.remote_principals``) may do,
together, and nothing more. Another robot's router (``site/robot1/supervisor`` on robot 2's)
matches no subject: denied everything. Each host's own router confines each of its own
principals on ingress, as on one host (docs/security.md, "Two hosts, secured").

Only the principals a stack has a use for get a secret (:func:`running_principals`: the router,
the processes of ``supervisor.services``, the tools and the other hosts' principals), while the
rules are built for every principal of the stack: one without a secret cannot log in at all.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from typing import Any

from common.access import Access, Shape
from common.errors import ConfigError
from common.keys import Keys
from common.security import (
    AUTH_MODES,
    DETECTOR_PRINCIPAL,
    ROUTER_PRINCIPAL,
    camera_services,
    role_of,
    stack_principals,
)
from common.service_list import SERVICES
from common.settings import (
    check_camera_name,
    is_detector_service,
    principal_name,
    service_package,
)
from services.controller import contract as controller
from services.recorder import contract as recorder
from stack.contracts import contracts, live_sensors

#: The packages whose services feed a live robot's sensors into the stack (their contracts'
#: ``LIVE_SENSOR``): while one of them runs, no recording may be played onto its keys.
LIVE_SENSORS = live_sensors()
#: A principal that may watch (subscribe, query) but publishes nothing: status lines, tests.
OBSERVER_PRINCIPAL = "observer"
#: The principals of the tools people run against a running stack, whatever services it runs:
#: ``zstack record`` and ``zstack play`` (as the recorder), ``zstack estop``, and the observer
#: (status lines, ``zstack query``, reports, scenario runs, tests).
TOOL_PRINCIPALS = (recorder.SERVICE, controller.ESTOP_PRINCIPAL, OBSERVER_PRINCIPAL)

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
#: The Zenoh message kinds each kind of an Access allows.
KIND_MESSAGES = {
    "put": ["put"],
    "token": ["liveliness_token"],
    "serve": ["declare_queryable", "reply"],
    "read": ["declare_subscriber"],
    # What a service watches (announcements, the pool's tokens), declared in its contract and
    # allowed by a rule of its own even while every principal may ask (the "ask" rule).
    "watch": ["declare_liveliness_subscriber", "liveliness_query"],
}


def running_sensors(services: Iterable[str]) -> list[str]:
    """Those of ``services`` that feed a live robot's sensors (any camera, the simulator, the
    ROS 2 bridge), sorted."""
    return sorted(s for s in set(services) if service_package(s) in LIVE_SENSORS)


def _observer(shape: Shape) -> dict[str, Access]:
    """Everything but the cameras' pictures: what status lines, tests and tools watch."""
    keys = shape.keys
    watching = (
        keys.all_detections(), keys.scan(), keys.cmd_vel(), keys.controller_status(),
        keys.estop(), keys.sim_truth(), keys.all_counters(),
    )  # fmt: skip
    return {OBSERVER_PRINCIPAL: Access(read=watching)}


def _check_remote(known: Iterable[str], remote: Iterable[str]) -> None:
    """ValueError, one line, for a name among ``remote`` that is none of ``known`` (or is the
    router's), or is written qualified (``site/robot1/camera``: the roles are written, and
    qualified here as this stack's, docs/security.md)."""
    known = [p for p in known if p != ROUTER_PRINCIPAL]
    if scoped := [p for p in dict.fromkeys(remote) if "/" in p]:
        raise ValueError(
            f"zenoh.remote_principals names {', '.join(map(repr, scoped))}: write the roles "
            f"({', '.join(repr(role_of(p)) for p in scoped)}); each router qualifies them as its "
            "own robot's (<stack.prefix>/<role>) or, for a detector worker, its pool's "
            "(<detector.pool_prefix>/<worker>)"
        )
    unknown = [p for p in dict.fromkeys(remote) if p not in known]
    if unknown:
        raise ValueError(
            f"zenoh.remote_principals names {', '.join(map(repr, unknown))}: not a principal of "
            f"this stack (known: {', '.join(known)}; another host's detector worker: "
            "detector_<worker_id>)"
        )


def linked_router_access(table: Mapping[str, Access], remote: Iterable[str]) -> Access:
    """What a linked router (another host's, admitted as ROUTER_PRINCIPAL) may do: what the
    ``remote`` principals (those the other hosts run) may do, together, in ``table``'s
    order. ValueError, one line, for a name that is no principal of the stack."""
    remote = tuple(dict.fromkeys(remote))
    _check_remote(table, remote)
    return merged(table[p] for p in remote)


def service_principals(
    services: Iterable[str],
    cameras: str | Mapping[str, str],
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The principals of the processes a supervisor that runs ``services``
    (``supervisor.services``) starts, as deploy/processes.py starts them: each camera's for
    ``camera``, each of ``workers`` for ``detector``, the service's own name otherwise."""
    out: list[str] = []
    for service in services:
        if service == "camera":
            out += camera_services(cameras).values()
        elif service == DETECTOR_PRINCIPAL:
            out += workers
        else:
            out.append(service)
    return tuple(dict.fromkeys(out))


def running_principals(
    services: Iterable[str],
    cameras: str | Mapping[str, str],
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
    remote: Iterable[str] = (),
) -> tuple[str, ...]:
    """The principals a stack that runs ``services`` has a use for: the router's, its
    processes' (:func:`service_principals`), the tools' (TOOL_PRINCIPALS) and those other hosts
    run (``remote``: ``zenoh.remote_principals``, another host's workers), in the order of
    :func:`stack_principals`. What ``zstack credentials`` makes; a principal left out (the
    ``camera`` of a stack that runs the simulator) has no secret, so nobody can log in as it.
    ValueError, one line, for a ``remote`` name that is no principal of the stack."""
    remote = tuple(remote)
    workers = tuple(workers)
    remote_workers = [p for p in remote if is_detector_service(p)]
    every = stack_principals(
        remote_cameras(camera_services(cameras), remote), (*workers, *remote_workers)
    )
    _check_remote(every, remote)
    wanted = {ROUTER_PRINCIPAL, *service_principals(services, cameras, workers)}
    wanted |= {*TOOL_PRINCIPALS, *remote}
    return tuple(p for p in every if p in wanted)


def access_table(shape: Shape, services: Iterable[str] = SERVICES) -> dict[str, Access]:
    """What each principal of the stack may do, from its service's contract. Puts name each
    configured camera's key: nobody may put on a camera the stack does not have. Reads and the
    detector's info take the wildcard, so that one subscription (or queryable) for every
    camera is accepted as well as one per camera; nobody can put on an unconfigured camera's
    key, so the wildcard reads nothing more. ``services``: the one list
    (common/service_list.py), each service's ``access`` read from its contract."""
    table: dict[str, Access] = {}
    for module in contracts(services).values():
        table.update(module.access(shape))
    return {
        **table,
        **controller.estop_access(shape),
        ROUTER_PRINCIPAL: Access(),  # its session lives inside the router: no rule applies to it
        **_observer(shape),
    }


def _table(
    keys: Keys,
    cameras: str | Mapping[str, str],
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
    prefixes: Iterable[str] = (),
    remote: Iterable[str] = (),
    pool_prefix: str = "",
) -> dict[str, Access]:
    """Each principal's access; with ``remote`` (the principals other hosts run), another
    host's detector workers among them, and the linked routers' (ROUTER_PRINCIPAL's)."""
    remote = tuple(remote)
    pool = tuple(dict.fromkeys((*workers, *(p for p in remote if is_detector_service(p)))))
    shape = Shape(
        keys, remote_cameras(camera_services(cameras), remote), pool, live_sensors,
        tuple(prefixes), pool_prefix,
    )  # fmt: skip
    table = access_table(shape)
    if remote:
        # A pool's router linked to the routers of the robots it serves: their principals
        # act on their own robot's keys, so the link may do what they may on each prefix.
        robots = (
            shape,
            *(
                dataclasses.replace(shape, keys=k, prefixes=(), pool_prefix="")
                for k in shape.other_robots()
            ),
        )
        tables = [table, *(access_table(r) for r in robots[1:])]
        table[ROUTER_PRINCIPAL] = merged(linked_router_access(t, remote) for t in tables)
        for robot, t in zip(robots, tables, strict=True):
            table[_linked(robot.keys.prefix)] = linked_router_access(t, remote)
    return table


def _linked(prefix: str) -> str:
    """The table's entry for the router of the robot of ``prefix``, linked to this one: what
    that robot's principals among the remote ones may do on that robot's keys alone."""
    return f"{ROUTER_PRINCIPAL}@{prefix}"


def remote_cameras(cameras: Mapping[str, str], remote: Iterable[str]) -> dict[str, str]:
    """``cameras`` (``{camera: principal}``) with each further camera another host runs:
    ``camera_<name>`` among the ``remote`` principals is camera ``<name>``, so that a GPU box,
    which has no camera table, admits the robot's cameras over the link. ValueError, one
    line, for a name that is no camera's."""
    out = dict(cameras)
    for principal in remote:
        if service_package(principal) != "camera" or principal in out.values():
            continue
        name = principal.removeprefix("camera_")
        try:
            check_camera_name(name)
        except ConfigError as exc:
            raise ValueError(f"zenoh.remote_principals names {principal!r}: {exc}") from exc
        out[name] = principal
    return out


def merged(accesses: Iterable[Access]) -> Access:
    """What any of ``accesses`` allows, in order."""
    out: dict[str, dict[str, None]] = {}
    for a in accesses:
        for kind, exprs in dataclasses.asdict(a).items():
            out.setdefault(kind, {}).update(dict.fromkeys(exprs))
    return Access(**{kind: tuple(exprs) for kind, exprs in out.items()})


def ask_scope(keys: Keys, prefixes: Iterable[str] = ()) -> list[str]:
    """Where to ask (query, watch and look up tokens): the stack's prefix, then ``prefixes``
    (every principal asks in the pool's; only the workers and a linked router in the further
    robots' their pool serves)."""
    return [f"{p}/**" for p in dict.fromkeys((keys.prefix, *prefixes))]


def pool_scope(keys: Keys, pool_prefix: str) -> list[str]:
    """Where every principal may ask in a pool of its own prefix (``detector.pool_prefix``):
    its tokens and announcements (``<pool>/detector/...``), not all of ``<pool>/**``, which
    holds the robots' prefixes too in a site's layout (``site`` and ``site/robot1``): robot 1's
    principals would ask robot 2's metrics through the links."""
    if not pool_prefix or pool_prefix == keys.prefix:
        return []
    return [f"{pool_prefix}/detector/**"]


def access_control(
    keys: Keys,
    cameras: str | Mapping[str, str],
    auth: str,
    principals: tuple[str, ...] | None = None,
    *,
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
    prefixes: Iterable[str] = (),
    remote: Iterable[str] = (),
    pool_prefix: str = "",
    linked: Iterable[str] = (),
) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for the router: deny by default, then allow each
    principal its own keys on ingress (puts, tokens, queryables, subscriptions), queries and
    liveliness for everyone within :func:`ask_scope`, and everything on egress (the router
    delivers only what it accepted, and only to subscriptions it accepted). Each rule's subject
    is a principal's name as it authenticates (common.settings.principal_name): this robot's
    ``<keys.prefix>/<role>``, a worker's ``<pool_prefix or keys.prefix>/<worker>``, the linked
    routers' ``<prefix>/supervisor`` for each prefix of ``linked`` (``zenoh.linked_routers``;
    empty: ``keys.prefix``); another robot's principals, its router's included, match no
    subject, so the default denies them everything, reads included. The roles are what the
    arguments name. ``cameras``: see
    common.security.camera_services; ``principals`` (default: stack_principals) limits the
    rules to those named; ``workers``: the detector workers' names (``Config.detector_services``),
    each a principal; ``prefixes``: the robot prefixes they serve (empty: the stack's own);
    ``pool_prefix``: where their pool lives (empty: the stack's prefix), where all may ask;
    ``remote``: the principals other hosts run, whose traffic a linked router brings
    (:func:`linked_router_access`; another host's workers are principals here too)."""
    if auth not in AUTH_MODES[1:]:
        raise ValueError(f"access control needs an authenticated mode, got {auth!r}")
    remote = tuple(remote)
    workers = tuple(workers)
    if principals is None:
        remote_workers = [p for p in remote if is_detector_service(p)]
        principals = stack_principals(cameras, (*workers, *remote_workers))
    prefixes = tuple(prefixes)
    match = "usernames" if auth == "password" else "cert_common_names"

    linked = tuple(linked) or (keys.prefix,)
    routers = [principal_name(p, ROUTER_PRINCIPAL) for p in dict.fromkeys(linked)]

    def names(role: str) -> list[str]:  # whose it is: this robot's, a worker its pool's,
        if role == ROUTER_PRINCIPAL:  # the router the linked routers'
            return routers
        return [principal_name(keys.prefix, role, pool_prefix)]

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
            "key_exprs": [*ask_scope(keys), *pool_scope(keys, pool_prefix)],
        },
    ]
    subjects: list[dict[str, Any]] = [
        {"id": "everyone", match: [n for p in principals for n in names(p)]}
    ]
    policies: list[dict[str, Any]] = [{"rules": ["egress", "ask"], "subjects": ["everyone"]}]
    served = [e for e in ask_scope(keys, prefixes) if e not in rules[-1]["key_exprs"]]
    if served:
        # The other robots a pool serves: only its workers may ask there (and each robot's
        # linked router in its own robot's prefix: _linked_rules).
        askers = [n for p in principals if is_detector_service(p) for n in names(p)]
        rules.append({**rules[-1], "id": "ask_served", "key_exprs": served})
        if askers:
            subjects.append({"id": "served_askers", match: askers})
            policies.append({"rules": ["ask_served"], "subjects": ["served_askers"]})
    table = _table(keys, cameras, live_sensors, workers, prefixes, remote, pool_prefix)
    for principal, allowed in table.items():
        if principal not in principals:
            continue
        if principal == ROUTER_PRINCIPAL and _linked(keys.prefix) in table:
            _linked_rules(table, keys, linked, match, rules, subjects, policies)
            continue
        subjects.append({"id": principal, match: names(principal)})
        ids = _kind_rules(principal, allowed, rules)
        if ids:
            policies.append({"rules": ids, "subjects": [principal]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _kind_rules(subject: str, allowed: Access, rules: list[dict[str, Any]]) -> list[str]:
    """Append an ingress rule per kind of message ``allowed`` names, for ``subject``; their
    ids."""
    ids = []
    for kind, key_exprs in allowed.kinds().items():
        rule_id = f"{subject}_{kind}"
        rules.append(
            {
                "id": rule_id,
                "messages": KIND_MESSAGES[kind],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": list(key_exprs),
            }
        )
        ids.append(rule_id)
    return ids


def _linked_rules(
    table: Mapping[str, Access],
    keys: Keys,
    linked: tuple[str, ...],
    match: str,
    rules: list[dict[str, Any]],
    subjects: list[dict[str, Any]],
    policies: list[dict[str, Any]],
) -> None:
    """A subject and rules per linked router (``<prefix>/supervisor`` for each prefix of
    ``linked``): what its own robot's principals among the remote ones may do, on that robot's
    keys alone, and asks in that robot's prefix; a pool's router linked to several robots so
    gives robot 1's router nothing of robot 2's. A linked router of no robot this stack serves
    (a GPU box's, on the robot it serves): what the remote principals may on this stack's keys.
    """
    own = table[_linked(keys.prefix)]
    for i, prefix in enumerate(dict.fromkeys(linked)):
        subject = f"linked_router_{i}"
        subjects.append({"id": subject, match: [principal_name(prefix, ROUTER_PRINCIPAL)]})
        ids = _kind_rules(subject, table.get(_linked(prefix), own), rules)
        if _linked(prefix) in table and prefix != keys.prefix:
            ask_id = f"{subject}_ask"
            rules.append(
                {
                    "id": ask_id,
                    "messages": list(_ASK_MESSAGES),
                    "flows": ["ingress"],
                    "permission": "allow",
                    "key_exprs": [f"{prefix}/**"],
                }
            )
            ids.append(ask_id)
        if ids:
            policies.append({"rules": ids, "subjects": [subject]})


def may_put(
    keys: Keys,
    cameras: str | Mapping[str, str],
    principal: str,
    *,
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The keys ``principal`` may put on (documentation and tests read the same table)."""
    allowed = _table(keys, cameras, live_sensors, workers).get(principal)
    return allowed.put if allowed else ()


def congestion_overwritten(
    keys: Keys,
    cameras: str | Mapping[str, str],
    *,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
    prefixes: Iterable[str] = (),
) -> tuple[str, ...]:
    """The keys on which the router puts congestion control DROP on every sample it takes in,
    whatever its publisher asked for: every key any principal may put on (a replay's too),
    but the e-stop. A client's BLOCK there would make the router wait on a full link (a frozen
    listener's) and hold up everyone's traffic behind it (docs/security.md, "QoS by role")."""
    puts: dict[str, None] = {}
    for live in (True, False):
        for allowed in _table(keys, cameras, live, workers, prefixes).values():
            puts.update(dict.fromkeys(allowed.put))
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
    allowed = _table(keys, cameras, workers=workers).get(principal)
    return allowed.token if allowed else ()


def may_read(keys: Keys, cameras: str | Mapping[str, str], principal: str) -> tuple[str, ...]:
    """The key expressions ``principal`` may subscribe to (within which any subscription)."""
    allowed = _table(keys, cameras).get(principal)
    return allowed.read if allowed else ()
