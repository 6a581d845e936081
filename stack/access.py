"""The router's access-control rules: Zenoh's ``access_control`` section, built from what each
principal may do (stack/access_table.py, from each service's contract). Pure: nothing here
opens a session; stack/hub.py hands the rules to the router.

Deny by default, then allow each principal its own keys on ingress (puts, tokens, queryables,
subscriptions). Zenoh allows a subscription only when its key expression lies within an
allowed one, so a wider one (``<prefix>/**``) is denied whole, not trimmed. Queries and
liveliness subscriptions are open to every principal, within the stack's prefix and the robot
prefixes its detector workers serve: nothing of another robot's on the same (or a linked)
router. Anything not allowed is denied.

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

Which principals get a secret at all: stack/principals.py (:func:`running_principals`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from common.access import Access
from common.keys import Keys
from common.security import AUTH_MODES, DETECTOR_PRINCIPAL, ROUTER_PRINCIPAL, stack_principals
from common.settings import is_detector_service, principal_name
from stack.access_table import linked_entry, stack_table

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
    table = stack_table(keys, cameras, live_sensors, workers, prefixes, remote, pool_prefix)
    for principal, allowed in table.items():
        if principal not in principals:
            continue
        if principal == ROUTER_PRINCIPAL and linked_entry(keys.prefix) in table:
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
    own = table[linked_entry(keys.prefix)]
    for i, prefix in enumerate(dict.fromkeys(linked)):
        subject = f"linked_router_{i}"
        subjects.append({"id": subject, match: [principal_name(prefix, ROUTER_PRINCIPAL)]})
        ids = _kind_rules(subject, table.get(linked_entry(prefix), own), rules)
        if linked_entry(prefix) in table and prefix != keys.prefix:
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
