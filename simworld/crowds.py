"""Crowds and occlusion (issue 41): worlds of 3 to 6 people, each of a body of their own
(simworld/body.py ``body_for``: height, build, clothes by id), where the robot must keep
following alice through the moments a follower fails on a real robot. Pure: the worlds; their
pass conditions are simworld/scenarios.py's.

The robot starts at the origin facing +x. Each world ends with alice standing at least
:data:`APART_M` from everyone else, so a robot at its stop distance from her, facing her, is
following her and no one else (the simulator's truth gives every person's id and position at
every tick, not whom the robot follows: tools/scenarios/score.py judges by where it ends).

- :func:`passing`: bob walks between the robot and alice.
- :func:`swap`: alice and bob, side by side, swap places, bob passing in front of her.
- :func:`pillar`: alice walks behind a pillar: hidden for 1-2 s (:data:`PILLAR`).
- :func:`fast_turn`: alice strides fast across the view and out of it: the robot must turn fast.
- :func:`crowd`: five people, three walking across each other's paths and alice's.
- :func:`handover`: alice strides out of the front camera's view into the left camera's, where
  bob stands near the bearing she is expected at: the lock must pass to her, not to him.
"""

from __future__ import annotations

import math

from simworld.cast import person
from simworld.world import Obstacle, Robot, World

#: Alice ends at least this far (m) from everyone else: a robot following another person ends
#: its stop distance (1 m) from them, beyond the scorer's reach tolerance from alice.
APART_M = 2.4


def passing() -> World:
    """Alice waits 5 m ahead, then walks slowly on; bob crosses the robot's view from right to
    left at a brisk 1 m/s, 3.2 m ahead, between the robot and alice at about 4 s; carol stands
    to the right, beyond."""
    alice = person("alice", (0.0, 5.0, 0.0), (4.0, 5.0, 0.0), (13.0, 8.5, 0.5))
    bob = person("bob", (0.0, 3.2, -2.5), (1.5, 3.2, -2.5), (6.5, 3.2, 2.5))
    carol = person("carol", (0.0, 6.5, -2.2))
    return World(Robot(), targets=[alice, bob, carol])


def swap() -> World:
    """Alice (right) and bob (left) stand side by side 6 m ahead; from 2 s they swap places,
    bob walking a little nearer the robot, in front of her; then they step apart, alice to the
    left, bob to the right. Carol stands between them, farther on."""
    alice = person("alice", (0.0, 6.0, -0.8), (2.0, 6.0, -0.8), (6.0, 6.2, 0.8),
                   (9.0, 6.5, 1.5))  # fmt: skip
    bob = person("bob", (0.0, 5.3, 0.8), (2.0, 5.3, 0.8), (6.0, 5.3, -0.8), (9.0, 6.5, -1.5))
    carol = person("carol", (0.0, 8.5, 0.0))
    return World(Robot(), targets=[alice, bob, carol])


#: The pillar (a solid column, 0.9 m across) alice walks behind, 7 m ahead.
PILLAR = Obstacle(7.0, 0.0, 0.45, height_m=2.5)
#: Alice crosses behind the pillar along x = PILLAR_ALICE_X at PILLAR_SPEED_MPS, from y = -1.5
#: (from PILLAR_START_S) to y = 1, then walks on to PILLAR_ALICE_END (to the robot's side of
#: the pillar, so the way to her is clear of it) and stands.
PILLAR_ALICE_X = 8.0
PILLAR_SPEED_MPS = 0.3
PILLAR_START_S = 1.0
PILLAR_ALICE_END = (6.0, 3.0)
#: When alice stands at PILLAR_ALICE_END (s).
PILLAR_END_S = PILLAR_START_S + (2.5 + math.hypot(2.0, 2.0)) / PILLAR_SPEED_MPS


def pillar() -> World:
    """A pillar 7 m ahead; alice stands 1 m beyond it, to its right, then walks across behind
    it to the left: from the robot (anywhere from its start to 3 m on) she is hidden for 1 to
    2 s. Then she comes forward, to the left, and stands. Bob and carol stand to either side."""
    across_s = PILLAR_START_S + 2.5 / PILLAR_SPEED_MPS
    alice = person("alice", (0.0, PILLAR_ALICE_X, -1.5), (PILLAR_START_S, PILLAR_ALICE_X, -1.5),
                   (across_s, PILLAR_ALICE_X, 1.0), (PILLAR_END_S, *PILLAR_ALICE_END))  # fmt: skip
    bob = person("bob", (0.0, 9.0, -2.8))
    carol = person("carol", (0.0, 3.5, 3.5))
    return World(Robot(), obstacles=[PILLAR], targets=[alice, bob, carol])


#: fast_turn: alice strides from her first place to her last at this speed (m/s), from 4 s.
FAST_SPEED_MPS = 1.5
FAST_FROM, FAST_TO, FAST_START_S = (2.2, -1.2), (2.2, 2.5), 4.0


def fast_turn() -> World:
    """Alice stands 2.5 m ahead, to the right; at 4 s she strides 3.7 m to the left at 1.5 m/s,
    out of the camera's view unless the robot turns at once (her bearing sweeps over 30 deg/s
    from the robot's start, faster from nearer her), and stands. Bob and carol stand farther
    on, in view."""
    end_s = FAST_START_S + 3.7 / FAST_SPEED_MPS
    alice = person("alice", (0.0, *FAST_FROM), (FAST_START_S, *FAST_FROM), (end_s, *FAST_TO))
    bob = person("bob", (0.0, 5.5, -2.0))
    carol = person("carol", (0.0, 5.0, 1.0))
    return World(Robot(), targets=[alice, bob, carol])


def crowd() -> World:
    """Five people: alice waits 3.5 m ahead and then walks on, to the left; bob crosses her
    path ahead of her, carol crosses it diagonally farther on, dave stands beyond, erin walks
    down the left side towards the robot."""
    alice = person("alice", (0.0, 3.5, 0.0), (3.0, 3.5, 0.0), (13.0, 7.5, 1.0))
    bob = person("bob", (0.0, 6.0, 2.5), (3.0, 6.0, 2.5), (10.0, 6.0, -2.5))
    carol = person("carol", (0.0, 8.5, -2.0), (4.0, 8.5, -2.0), (12.0, 5.5, 2.5))
    dave = person("dave", (0.0, 9.5, -1.0))
    erin = person("erin", (0.0, 10.0, 2.0), (15.0, 4.0, 3.0))
    return World(Robot(), targets=[alice, bob, carol, dave, erin])


#: handover: alice strides from ahead into the left camera's view at this speed (m/s), from
#: HANDOVER_START_S, then walks on at HANDOVER_WALK_MPS; bob stands where the left camera sees
#: him within the controller's hand-over gate (20 deg) of her bearing as she arrives.
HANDOVER_SPEED_MPS, HANDOVER_WALK_MPS, HANDOVER_START_S = 1.5, 0.5, 4.0
HANDOVER_FROM, HANDOVER_MID, HANDOVER_TO = (2.2, 0.3), (0.4, 2.0), (-1.5, 3.5)
HANDOVER_BOB = (1.2, 2.6)


def handover_end_s() -> float:
    """When alice stands still at her last place in :func:`handover`."""
    stride = math.dist(HANDOVER_FROM, HANDOVER_MID) / HANDOVER_SPEED_MPS
    return HANDOVER_START_S + stride + math.dist(HANDOVER_MID, HANDOVER_TO) / HANDOVER_WALK_MPS


def handover() -> World:
    """Alice stands 2.2 m ahead; at 4 s she strides up and to the left, out of the front
    camera's view (faster than the robot turns) into the left camera's, and walks on to
    stand behind and to the left. Bob stands in the left camera's view, 10 deg or so from her
    bearing as she comes into it; carol stands far ahead in the front camera's view."""
    mid_s = HANDOVER_START_S + math.dist(HANDOVER_FROM, HANDOVER_MID) / HANDOVER_SPEED_MPS
    alice = person("alice", (0.0, *HANDOVER_FROM), (HANDOVER_START_S, *HANDOVER_FROM),
                   (mid_s, *HANDOVER_MID), (handover_end_s(), *HANDOVER_TO))  # fmt: skip
    bob = person("bob", (0.0, *HANDOVER_BOB))
    carol = person("carol", (0.0, 5.5, -1.5))
    return World(Robot(), targets=[alice, bob, carol])
