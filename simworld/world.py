"""The simulated world: a unicycle robot, static obstacles, walls, drop-offs and scripted targets.
Pure.

World frame: x forward at the start, y to the left, theta counter-clockwise (REP 103). The
robot integrates the latest Twist under its own speed and acceleration limits, like a real
base, and stops by itself when commands stop arriving (its watchdog).

The hazards are as hard as a real floor's for a robot that sees by depth: an obstacle has a
height and a material (:class:`Material`: what a laser and a depth camera make of it), and the
floor may drop away (:class:`Drop`: a kerb, a step), which no planar laser sees. A room is
walls (:class:`Wall`: straight segments of a height and a material) that hide what is behind
them from the cameras and the laser.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from enum import StrEnum

import numpy as np
import numpy.typing as npt

from common.unicycle import advance
from simworld.body import Body


@dataclass(frozen=True, slots=True)
class BaseLimits:
    """The base's own limits: what the motors can do, whatever the controller asks."""

    max_linear: float = 0.6
    max_angular: float = 1.5
    max_linear_accel: float = 1.5
    max_angular_accel: float = 4.0
    watchdog_s: float = 0.5
    # A command over this many times a limit is no command a sane controller sends: the base
    # refuses it and stops, as real bases fault on out-of-range input rather than clamp it.
    refuse_over: float = 2.0


@dataclass(slots=True)
class Robot:
    """Pose (x, y, theta) and current velocities (v, w)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    v: float = 0.0
    w: float = 0.0
    radius: float = 0.25

    def step(self, cmd: tuple[float, float], dt: float, lim: BaseLimits) -> None:
        """Move towards the commanded (v, w) within the limits, then integrate the pose."""
        v_goal = min(max(cmd[0], -lim.max_linear), lim.max_linear)
        w_goal = min(max(cmd[1], -lim.max_angular), lim.max_angular)
        dv = min(max(v_goal - self.v, -lim.max_linear_accel * dt), lim.max_linear_accel * dt)
        dw = min(max(w_goal - self.w, -lim.max_angular_accel * dt), lim.max_angular_accel * dt)
        self.v += dv
        self.w += dw
        # Exact unicycle integration over dt for constant (v, w).
        self.x, self.y, theta = advance((self.x, self.y, self.theta), self.v, self.w, dt)
        self.theta = math.atan2(math.sin(theta), math.cos(theta))


class Material(StrEnum):
    """What an obstacle's surface does to the robot's sensors.

    The two sensors a small robot carries fail on different things, and a world where every
    obstacle is seen by both proves nothing about either alone. A depth camera reads nothing
    on some (dark, glass) and reads wrong on others (mirror).
    """

    SOLID = "solid"  # the depth camera reads its face; the laser sees it (if tall enough)
    # Black (a bin, a rubber mat on a post): a stereo or structured-light camera finds no
    # texture and no reflected pattern on it, so its face reads nothing; a lidar still sees it.
    DARK = "dark"
    # A glass pane or door: a lidar's beam passes through, a depth camera reads nothing on it
    # (or what is behind); the colour image shows what is behind it.
    GLASS = "glass"
    # A mirror or polished steel (a lift door, a stainless bin): it reads WRONG. A depth
    # camera finds there what the mirror reflects, farther than the face (sim.depth_mirror_scale
    # times its depth; simworld/faults.py mirror_reads), so its face seems to stand back or to
    # be a hole in the floor; the laser still sees it (a real lidar may lose a mirror at a
    # glancing angle: not modelled). The colour image shows a bright steel box.
    MIRROR = "mirror"


@dataclass(frozen=True, slots=True)
class Obstacle:
    """A round obstacle (a pillar, a bin, a pane): centre and footprint radius in metres, its
    height above the floor (metres) and its :class:`Material`."""

    x: float
    y: float
    radius: float
    height_m: float = 0.5
    material: Material = Material.SOLID

    def __post_init__(self) -> None:
        # "glass" as well as Material.GLASS; a name that is no material fails here, at build.
        object.__setattr__(self, "material", Material(self.material))


@dataclass(frozen=True, slots=True)
class Drop:
    """A drop-off: an axis-aligned rectangle of the world frame (x0 <= x1, y0 <= y1, metres)
    where the floor is ``depth_m`` lower (a kerb 0.15 m, a step or stairwell 0.5 m). A planar
    laser never sees one; only a camera looking down at the floor can."""

    x0: float
    y0: float
    x1: float
    y1: float
    depth_m: float

    def distance(self, x: float, y: float) -> float:
        """From the point (x, y) to the rectangle's edge, signed: negative inside it (how far
        in from the nearest edge), so a figure over a run says how far over the edge it went."""
        dx = max(self.x0 - x, x - self.x1)
        dy = max(self.y0 - y, y - self.y1)
        if dx <= 0 and dy <= 0:
            return max(dx, dy)
        return math.hypot(max(dx, 0.0), max(dy, 0.0))


@dataclass(frozen=True, slots=True)
class Wall:
    """A straight wall from (x0, y0) to (x1, y1) (metres, world frame), standing on the floor,
    ``height_m`` tall, of no thickness, its surface a :class:`Material` (solid, dark or glass;
    a mirror wall is not modelled: a mirror is a round :class:`Obstacle`). The laser sees it
    where it is taller than the laser's plane and not glass; the cameras draw it as a quad in
    perspective (simworld/walls.py), hiding what is behind it unless it is glass."""

    x0: float
    y0: float
    x1: float
    y1: float
    height_m: float = 2.5
    material: Material = Material.SOLID

    def __post_init__(self) -> None:
        object.__setattr__(self, "material", Material(self.material))
        if self.material == Material.MIRROR:
            raise ValueError("a mirror wall is not modelled: use a round Obstacle of MIRROR")
        if (self.x0, self.y0) == (self.x1, self.y1) or self.height_m <= 0:
            raise ValueError(f"a wall needs a length and a height: {self}")

    def distance(self, x: float, y: float) -> float:
        """From the point (x, y) to the nearest point of the wall (metres)."""
        ex, ey = self.x1 - self.x0, self.y1 - self.y0
        a = ((x - self.x0) * ex + (y - self.y0) * ey) / (ex * ex + ey * ey)
        a = min(max(a, 0.0), 1.0)
        return math.hypot(x - (self.x0 + a * ex), y - (self.y0 + a * ey))


#: A flat-card person's height (m): the simple world's, every person's before bodies.
CARD_HEIGHT_M = 1.7


@dataclass(frozen=True, slots=True)
class Target:
    """Something the camera can see: a class, a cut-out, a size, and a scripted path.

    ``path`` is a list of (t, x, y) waypoints; the target moves linearly between them and stays
    at the last. One waypoint means it stands still. With ``loop`` the path repeats: its last
    waypoint should equal its first.

    ``body``: a person's body (simworld/body.py), drawn as their silhouette with a rounded
    depth, facing and walking; its height is the target's. None: the flat photo cut-out
    ``sprite``, one depth over its whole rectangle (the simple world, :func:`flat_world`).
    ``radius`` is the footprint the laser sees either way.
    """

    id: str
    name: str
    sprite: str
    height_m: float
    path: tuple[tuple[float, float, float], ...]
    radius: float = 0.25
    mirror: bool = False
    loop: bool = False
    body: Body | None = None

    def __post_init__(self) -> None:
        if self.body is not None and self.body.height_m != self.height_m:
            raise ValueError(
                f"target {self.id}: height {self.height_m} m, its body's {self.body.height_m} m"
            )

    def position(self, t: float) -> tuple[float, float]:
        pts = self.path
        if self.loop and t > pts[0][0] and pts[-1][0] > pts[0][0]:
            t = pts[0][0] + (t - pts[0][0]) % (pts[-1][0] - pts[0][0])
        if t <= pts[0][0]:
            return pts[0][1], pts[0][2]
        for (t0, x0, y0), (t1, x1, y1) in itertools.pairwise(pts):
            if t <= t1:
                a = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
                return x0 + a * (x1 - x0), y0 + a * (y1 - y0)
        return pts[-1][1], pts[-1][2]


@dataclass(slots=True)
class World:
    """Everything that exists, and the simulation clock."""

    robot: Robot
    obstacles: list[Obstacle] = field(default_factory=list)
    drops: list[Drop] = field(default_factory=list)
    targets: list[Target] = field(default_factory=list)
    limits: BaseLimits = field(default_factory=BaseLimits)
    t: float = 0.0
    last_cmd: tuple[float, float] = (0.0, 0.0)
    last_cmd_t: float = -math.inf
    walls: list[Wall] = field(default_factory=list)

    def command(self, v: float, w: float) -> bool:
        """A Twist arrived; False (and the base stops) when it is beyond what the base takes."""
        lim = self.limits
        sane = abs(v) <= lim.max_linear * lim.refuse_over and abs(w) <= (
            lim.max_angular * lim.refuse_over
        )
        self.last_cmd, self.last_cmd_t = ((v, w) if sane else (0.0, 0.0)), self.t
        return sane

    def advance(self, dt: float) -> None:
        fresh = self.t - self.last_cmd_t <= self.limits.watchdog_s
        self.robot.step(self.last_cmd if fresh else (0.0, 0.0), dt, self.limits)
        self.t += dt

    def target_positions(self) -> npt.NDArray[np.float64]:
        if not self.targets:
            return np.zeros((0, 2))
        return np.array([tg.position(self.t) for tg in self.targets], np.float64)

    def obstacle_circles(self) -> npt.NDArray[np.float64]:
        """The obstacles alone as (x, y, r) rows, (m, 3)."""
        rows = [(o.x, o.y, o.radius) for o in self.obstacles]
        return np.array(rows, np.float64).reshape(-1, 3)

    def circles(self) -> npt.NDArray[np.float64]:
        """Every solid thing as (x, y, r) rows: obstacles and targets, whatever their height
        and material (what a laser at floor level that saw through nothing would see)."""
        rows = [(o.x, o.y, o.radius) for o in self.obstacles]
        rows += [(*tg.position(self.t), tg.radius) for tg in self.targets]
        return np.array(rows, np.float64).reshape(-1, 3)

    def laser_circles(self, laser_height_m: float) -> npt.NDArray[np.float64]:
        """What a planar laser ``laser_height_m`` above the floor sees, as (x, y, r) rows: the
        obstacles taller than its plane and not glass (its beam passes through), and the
        targets (people and things standing on the floor, taken as tall enough)."""
        rows = [
            (o.x, o.y, o.radius)
            for o in self.obstacles
            if o.height_m > laser_height_m and o.material != Material.GLASS
        ]
        rows += [(*tg.position(self.t), tg.radius) for tg in self.targets]
        return np.array(rows, np.float64).reshape(-1, 3)

    def laser_walls(self, laser_height_m: float) -> npt.NDArray[np.float64]:
        """The walls a planar laser ``laser_height_m`` above the floor sees, as (x0, y0, x1, y1)
        rows: those taller than its plane and not glass."""
        rows = [
            (w.x0, w.y0, w.x1, w.y1)
            for w in self.walls
            if w.height_m > laser_height_m and w.material != Material.GLASS
        ]
        return np.array(rows, np.float64).reshape(-1, 4)

    def clearance(self) -> float:
        """Distance from the robot's edge to the nearest obstacle's edge or wall (inf if none)."""
        r = self.robot
        return min(
            [math.hypot(o.x - r.x, o.y - r.y) - o.radius - r.radius for o in self.obstacles]
            + [w.distance(r.x, r.y) - r.radius for w in self.walls],
            default=math.inf,
        )


def flat_world(world: World) -> World:
    """``world`` with every person's body taken away: each the flat photo cut-out of
    :data:`CARD_HEIGHT_M` (the simple world, as the simulator drew every person before
    bodies). A new world (its robot a copy); ``world`` is left as it was."""
    return replace(
        world,
        robot=replace(world.robot),
        targets=[
            tg if tg.body is None else replace(tg, body=None, height_m=CARD_HEIGHT_M)
            for tg in world.targets
        ],
        obstacles=list(world.obstacles),
        drops=list(world.drops),
        walls=list(world.walls),
    )
