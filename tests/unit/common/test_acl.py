"""Zenoh's access-control section as the in-process bus reads it (common/acl.py)."""

from __future__ import annotations

import pytest

from common.acl import AccessRules, includes


@pytest.mark.parametrize(
    ("outer", "inner", "within"),
    [
        ("a/b", "a/b", True),
        ("a/b", "a/c", False),
        ("a/*", "a/b", True),
        ("a/*", "a/*", True),
        ("a/b", "a/*", False),  # a wider subscription is denied whole, not trimmed
        ("a/*", "a/b/c", False),
        ("a/**", "a", True),  # ** takes no chunk too
        ("a/**", "a/b/c", True),
        ("a/**", "a/*/c", True),
        ("a/**", "a/**", True),
        ("a/*/c", "a/**", False),
        ("a/*/c", "a/b/c", True),
        ("**", "x/y", True),
        ("a/b/**", "a/**", False),
        ("a", "a/b", False),
        ("a/b", "a", False),
    ],
)
def test_includes(outer: str, inner: str, within: bool) -> None:
    assert includes(outer, inner) is within


def _section(**extra: object) -> dict[str, object]:
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            {
                "id": "cam_put",
                "messages": ["put"],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": ["s/camera/front/frame"],
            },
            {
                "id": "out",
                "messages": ["put", "declare_subscriber"],
                "flows": ["egress"],
                "permission": "allow",
                "key_exprs": ["**"],
            },
        ],
        "subjects": [{"id": "cam", "usernames": ["camera"]}, {"id": "all", "usernames": ["x"]}],
        "policies": [
            {"rules": ["cam_put"], "subjects": ["cam"]},
            {"rules": ["out"], "subjects": ["all"]},
        ],
        **extra,
    }


def test_only_ingress_allow_rules_of_the_principals_own_subjects_count() -> None:
    rules = AccessRules(_section())
    assert rules.allows("camera", "put", "s/camera/front/frame")
    assert not rules.allows("camera", "put", "s/camera/rear/frame")
    assert not rules.allows("camera", "declare_subscriber", "s/camera/front/frame")
    assert not rules.allows("x", "put", "s/camera/front/frame")  # an egress rule only
    assert not rules.allows("nobody", "put", "s/camera/front/frame")


def test_what_it_cannot_read_is_refused() -> None:
    with pytest.raises(ValueError, match="not enabled"):
        AccessRules({"enabled": False})
    with pytest.raises(ValueError, match="default_permission"):
        AccessRules(_section(default_permission="allow"))
    deny = _section()
    deny["rules"][0]["permission"] = "deny"  # type: ignore[index]
    with pytest.raises(ValueError, match="only 'allow' rules"):
        AccessRules(deny)
