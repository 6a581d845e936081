"""The truth a tracker is scored against (simworld/truth.py): each person's box as a camera
shows it, cut where a nearer person hides them or the image's edge ends, with the share that
shows."""

from __future__ import annotations

import pytest

from simworld.cast import card, person
from simworld.render import CameraSpec
from simworld.truth import visible_boxes
from simworld.world import Robot, World

SPEC = CameraSpec(640, 480, 60.0, 0.6)


def test_a_person_in_full_view_shows_whole_and_one_behind_another_partly() -> None:
    alone = World(Robot(), targets=[card("alice", (0, 4.0, 0.0))])
    [a] = visible_boxes(alone, SPEC)
    assert a.target == "alice" and a.name == "person" and a.visible == pytest.approx(1.0)
    x0, _, x1, _ = a.box
    assert x0 < 320 < x1  # straight ahead: round the image's middle
    # bob stands nearer, to the left of alice's line: he hides her left part (and the image's
    # top cuts his head: at 2 m the card is taller than the view).
    both = World(Robot(), targets=[card("alice", (0, 4.0, 0.0)), card("bob", (0, 2.0, 0.6))])
    hidden, bob = visible_boxes(both, SPEC)
    assert (hidden.target, bob.target) == ("alice", "bob")
    assert bob.box[1] == 0 and 0.5 < bob.visible < 1.0
    assert 0.0 < hidden.visible < 0.9
    assert hidden.box[0] > x0  # her box starts where bob's ends
    # Wholly hidden: not shown at all; cut at the image's edge: a share.
    behind = World(Robot(), targets=[card("alice", (0, 4.0, 0.0)), card("bob", (0, 1.0, 0.0))])
    assert [b.target for b in visible_boxes(behind, SPEC)] == ["bob"]
    edge = World(Robot(), targets=[card("alice", (0, 2.0, 1.2))])
    [cut] = visible_boxes(edge, SPEC)
    assert cut.box[0] == 0 and 0.0 < cut.visible < 1.0
    assert visible_boxes(edge, SPEC, min_visible=0.95) == []


def test_a_body_s_box_is_its_silhouette_not_its_canvas() -> None:
    world = World(Robot(), targets=[person("alice", (0, 3.0, 0.0))])
    [b] = visible_boxes(world, SPEC)
    x0, y0, x1, y1 = b.box
    assert b.visible == pytest.approx(1.0, abs=0.02)  # its stamp scaled to whole pixels
    assert (x1 - x0) < 0.5 * (y1 - y0)  # a standing person: tall and narrow
