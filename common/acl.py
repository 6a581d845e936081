"""Zenoh's ``access_control`` section read as the router reads it, for the in-process bus.

Pure: no bus. stack/access.py writes the section (``access_control``) that the supervisor's
router enforces; :class:`AccessRules` reads the same dict and answers what the router would:
may ``principal`` send a message of ``kind`` on a key expression, on ingress. The kinds the
stack's rules use: ``put``, ``liveliness_token``, ``declare_queryable``, ``reply``,
``declare_subscriber``, and the asking kinds (``query``, ``declare_liveliness_subscriber``,
``liveliness_query``). As the router does, a declaration (a subscription, a token, a queryable)
is allowed only when its key expression lies *within* an allowed one (a wider one is denied
whole, never trimmed), and a put only on a key an allowed expression includes. Egress rules
are not checked: the stack's allow everything on egress (the router delivers only what it
accepted on ingress).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: The subject fields that name principals (password and certificate authentication).
SUBJECT_FIELDS = ("usernames", "cert_common_names")


def includes(outer: str, inner: str) -> bool:
    """Whether every key that key expression ``inner`` matches is matched by ``outer``
    (``*``: one chunk, ``**``: any number of chunks, none included)."""
    return _within(tuple(outer.split("/")), tuple(inner.split("/")))


def _within(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    if a and a[0] == "**":
        # a's ** takes none of b, or b's first chunk (whatever it is, a wildcard included)
        return _within(a[1:], b) or (bool(b) and _within(a, b[1:]))
    if not a or not b:
        return not a and not b
    if b[0] == "**":
        return False  # only a ** covers a **
    if b[0] == "*":
        return a[0] == "*" and _within(a[1:], b[1:])
    return (a[0] == "*" or a[0] == b[0]) and _within(a[1:], b[1:])


class AccessRules:
    """What each principal may do on ingress, from an ``access_control`` dict."""

    def __init__(self, section: Mapping[str, Any]) -> None:
        if not section.get("enabled", False):
            raise ValueError("access control is not enabled in this section")
        default = section.get("default_permission", "deny")
        if default != "deny":
            raise ValueError(f"only default_permission 'deny' is read, got {default!r}")
        rules = {rule["id"]: rule for rule in section.get("rules", ())}
        for rule in rules.values():
            if rule.get("permission") != "allow":
                raise ValueError(f"rule {rule['id']!r}: only 'allow' rules are read")
        subjects: dict[str, set[str]] = {}
        for subject in section.get("subjects", ()):
            names = subjects.setdefault(subject["id"], set())
            for field in SUBJECT_FIELDS:
                names.update(subject.get(field, ()))
        # principal -> message kind -> allowed key expressions
        self._allowed: dict[str, dict[str, list[str]]] = {}
        for policy in section.get("policies", ()):
            principals = set().union(*(subjects.get(s, set()) for s in policy["subjects"]))
            for rule_id in policy["rules"]:
                rule = rules[rule_id]
                if "ingress" not in rule.get("flows", ("ingress", "egress")):
                    continue
                for principal in principals:
                    kinds = self._allowed.setdefault(principal, {})
                    for kind in rule["messages"]:
                        kinds.setdefault(kind, []).extend(rule["key_exprs"])

    def allows(self, principal: str, kind: str, key_expr: str) -> bool:
        """Whether ``principal`` may send a ``kind`` message on ``key_expr``: it lies within
        one of the key expressions an allow rule gives the principal for that kind."""
        allowed = self._allowed.get(principal, {}).get(kind, ())
        return any(includes(expr, key_expr) for expr in allowed)
