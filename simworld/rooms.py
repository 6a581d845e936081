"""Rooms, not a corridor (issue 41): alice walks through rooms joined by a doorway, among
walls, other people and every kind of hazard a small robot's sensors miss. Pure: the worlds;
their pass conditions are simworld/scenarios.py's.

The robot starts at the origin facing +x. A room's walls are 2.5 m tall and solid; its
doorway is :data:`DOOR_WIDTH_M` wide, so a robot through its middle keeps a metre from each
jamb (the scorer's safety distance, 0.5 m from the robot's centre, counts walls).

Each hazard kind of the hazard scenarios (simworld/scenarios.py ``HAZARDS``) stands in a room,
off alice's path by more than the safety distance plus the robot's radius, so a robot that
follows her where she walks passes them all and one that strays meets one:

- a low box (0.15 m, under the laser's 0.2 m plane: only a camera sees it),
- a thin pole (r 0.03 m: a few laser rays, a few depth columns),
- a dark box (no depth reading on its face; the laser sees it),
- a glass pane (a wall 1 m tall: the laser passes through, the depth camera reads nothing),
- a mirror (a steel bin: the depth camera reads it farther than it is),
- a drop-off (a step down: no laser sees it).

:func:`rooms` has alice walk through two rooms and stop with the step behind her;
:func:`step_room`'s alice walks on down a step into a sunken room, where the robot must not
follow: it passes only by stopping at the edge.
"""

from __future__ import annotations

from simworld.cast import person
from simworld.world import Drop, Material, Obstacle, Robot, Wall, World

#: The rooms' walls' height (m) and a doorway's width (m).
ROOM_WALL_M = 2.5
DOOR_WIDTH_M = 2.0
#: The rooms' half-width (m): their side walls at y = +-ROOM_HALF_M.
ROOM_HALF_M = 2.5
#: The step down of :func:`rooms` (behind alice at the end) and of :func:`step_room` (m).
ROOMS_STEP_M = 0.3
STEP_ROOM_M = 0.2


def _box(x0: float, x1: float) -> list[Wall]:
    """A room from x0 to x1 (m), ROOM_HALF_M either side of y = 0: its side walls, and its
    end walls with no doorway."""
    h, y = ROOM_WALL_M, ROOM_HALF_M
    return [Wall(x0, -y, x1, -y, h), Wall(x0, y, x1, y, h), Wall(x0, -y, x0, y, h),
            Wall(x1, -y, x1, y, h)]  # fmt: skip


def _doorway(x: float) -> list[Wall]:
    """A partition at ``x`` across the rooms with a doorway DOOR_WIDTH_M wide, centred on
    y = 0."""
    h, y, d = ROOM_WALL_M, ROOM_HALF_M, DOOR_WIDTH_M / 2
    return [Wall(x, -y, x, -d, h), Wall(x, d, x, y, h)]


#: rooms: the partition's x and the far wall's (m).
ROOMS_DOOR_X, ROOMS_END_X = 7.0, 14.0
#: rooms: alice's last waypoint (m), where she stands from 22.5 s on.
ROOMS_ALICE_END = (11.5, -1.0)


def rooms() -> World:
    """Two rooms, 8.5 and 7 m long, joined by a doorway at x = 7. Alice waits 2.5 m ahead,
    walks to the doorway, through it and into the second room, and stands by its far corner
    with a step down behind her. Bob stands in the first room, carol walks along the second
    room's far side. Hazards off her path: a low box and a thin pole in the first room, a dark
    box, a glass pane, a mirror and a step down (a sunken corner) in the second."""
    alice = person("alice", (0.0, 2.5, 0.0), (4.0, 2.5, 0.0), (10.0, 5.5, 0.0),
                   (18.0, 9.5, 0.0), (22.5, *ROOMS_ALICE_END))  # fmt: skip
    bob = person("bob", (0.0, 4.0, 1.8))
    carol = person("carol", (0.0, 12.0, 2.1), (10.0, 12.0, 2.1), (17.0, 9.0, 1.8))
    return World(
        Robot(),
        walls=[*_box(-1.5, ROOMS_END_X), *_doorway(ROOMS_DOOR_X),
               Wall(10.0, -2.0, 11.0, -2.0, height_m=1.0, material=Material.GLASS)],
        obstacles=[
            Obstacle(3.0, -1.2, 0.25, height_m=0.15),  # a low box, under the laser
            Obstacle(5.5, -1.3, 0.03, height_m=1.2),  # a thin pole
            Obstacle(8.5, 1.5, 0.3, height_m=0.5, material=Material.DARK),  # a black bin
            Obstacle(12.8, 0.5, 0.25, height_m=0.9, material=Material.MIRROR),  # a steel bin
        ],
        drops=[Drop(12.2, -ROOM_HALF_M, ROOMS_END_X, -0.5, ROOMS_STEP_M)],
        targets=[alice, bob, carol],
    )  # fmt: skip


#: step_room: the partition's x, the step's edge (the sunken room beyond it) and the far wall.
STEP_DOOR_X, STEP_EDGE_X, STEP_END_X = 6.0, 7.0, 12.0
#: step_room: where alice ends, down the step (m), from 15 s on.
STEP_ALICE_END = (8.5, 0.3)


def step_room() -> World:
    """A room and, through a doorway at x = 6, a sunken room whose floor is a step lower from
    x = 7 on. Alice waits 2.5 m ahead, walks through the doorway and down the step, and stands
    in the sunken room 1.5 m beyond its edge: a follower wants to go on, the robot must stop
    at the edge. Bob walks across the first room behind her, carol stands in the sunken room.
    Around alice's path in the first room: a low box, a black pole, a glass pane, a mirror."""
    alice = person("alice", (0.0, 2.5, 0.0), (3.0, 2.5, 0.0), (8.0, 5.0, 0.0),
                   (15.0, *STEP_ALICE_END))  # fmt: skip
    bob = person("bob", (0.0, 5.0, 1.9), (6.0, 5.0, 1.9), (13.0, 2.0, 1.9))
    carol = person("carol", (0.0, 10.5, -1.5))
    return World(
        Robot(),
        walls=[*_box(-1.5, STEP_END_X), *_doorway(STEP_DOOR_X),
               Wall(1.5, -1.6, 2.5, -1.6, height_m=1.0, material=Material.GLASS)],
        obstacles=[
            Obstacle(3.5, 1.2, 0.25, height_m=0.15),  # a low box, under the laser
            Obstacle(4.5, -1.0, 0.03, height_m=1.2, material=Material.DARK),  # a black pole
            Obstacle(1.0, 1.6, 0.25, height_m=0.9, material=Material.MIRROR),  # a steel bin
        ],
        drops=[Drop(STEP_EDGE_X, -ROOM_HALF_M, STEP_END_X, ROOM_HALF_M, STEP_ROOM_M)],
        targets=[alice, bob, carol],
    )  # fmt: skip
