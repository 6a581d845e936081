"""The people of the scenarios: a person with a body of their own, or the flat card. Pure."""

from __future__ import annotations

from simworld.body import Body, body_for
from simworld.world import CARD_HEIGHT_M, Target


def person(
    id: str,
    *path: tuple[float, float, float],
    mirror: bool = False,
    body: Body | None = None,
    flat: bool = False,
) -> Target:
    """A person walking ``path`` (world.Target's waypoints). By default they have a body of
    their own look, the same for the same ``id`` (simworld/body.py :func:`body_for`), or
    ``body``; ``flat``: the flat photo cut-out of :data:`CARD_HEIGHT_M` (``mirror``: flipped
    left-right), as in the simple world."""
    if flat:
        return Target(id, "person", "person", CARD_HEIGHT_M, path, mirror=mirror)
    b = body_for(id) if body is None else body
    return Target(id, "person", "person", b.height_m, path, mirror=mirror, body=b)


def card(id: str, *path: tuple[float, float, float], mirror: bool = False) -> Target:
    """A flat-card person (:func:`person` with ``flat``)."""
    return person(id, *path, mirror=mirror, flat=True)
