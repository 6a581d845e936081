"""The depth benchmark's worlds, its cameras and its truths.

:func:`make_world`: the robot at the origin, one to three people (half of the others
overlapping the first in the image, in front of or behind them; in 40 % of the worlds a low
bin hides the first's legs) placed so that the range bands up to the depth camera's maximum
are evenly filled. Each person has a body of their own (simworld/body.py ``body_for``: height,
build, clothes, dark ones included) and stands facing a random way or walks through their
place (a random direction, 0.8-1.4 m/s, legs and arms mid-stride), their look and pose drawn
from a stream of their own so that the simple world (the same people as flat cards) places
everyone where the hard one does.

:class:`Camera`: the world as the simulator renders it (services/sim/worlds.py): ``"hard"``
(the default, ``sim.world``'s) with the harder camera's faults from ``SimSettings()``'s
defaults (:func:`~services.sim.worlds.depth_noise`: D435-class noise, range bias, flying
pixels at edges; the colour camera's motion blur and exposure, the robot having turned at a
random rate for the last :data:`TURN_S`), ``"simple"`` with today's camera and every person
the flat card of before (:func:`~services.sim.worlds.world_for`).

:func:`truths`: each target the camera sees, its true visible box (the bounding box of the
pixels it owns: simworld/depth.py ``owners``) and the points each method is held to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from common.images import Image
from services.sim.contract import SimSettings, SimWorld
from services.sim.worlds import colour_faults_of, depth_noise, world_for
from simworld.body import body_for
from simworld.depth import Depth, DepthNoise, apply, owners, render_depth, targets_in_camera
from simworld.faults import ColourFaults, Exposure, colour_faults, mirror_reads
from simworld.render import CameraSpec, render
from simworld.scenarios import person
from simworld.world import Obstacle, Robot, Target, World

#: The camera's horizontal field of view (degrees), as the simulator's default camera's.
HFOV_DEG = 60.0
#: The robot turned at a rate uniform in +-:data:`TURN_RATE` (rad/s) for the last
#: :data:`TURN_S` seconds before each frame (a follower's gentle correction): the colour
#: camera's motion blur (at most 0.25 x 20 ms x 554 px = 2.8 px) and its exposure lagging the
#: light (hard world only). Faster turns blur more than the detector takes at range: at 0.45
#: rad/s (5 px) it lost people it found at 6.7 and 7.2 m with scores 0.9 (docs/benchmarks.md).
TURN_RATE = 0.25
TURN_S = 0.5
#: A walking person's speed (m/s), uniform in this range; half the people walk.
WALK_MPS = (0.8, 1.4)
#: The share of targets the camera must see for a target to count (as targets_in_camera's).
MIN_VISIBLE = 0.3


def settings_for(world: str) -> SimSettings:
    """The simulator's default settings in ``world`` ("hard" or "simple")."""
    return SimSettings(world=SimWorld(world))


def _person(
    key: str, seed: int, look: np.random.Generator, at: tuple[float, float], mirror: bool
) -> Target:
    """A person of their own body at ``at`` (x, y) at time 1 s: facing a random way, or
    walking through it (``mirror``: their card's, in the simple world)."""
    body = body_for(key, seed)
    facing = float(look.uniform(-180.0, 180.0))
    walks = bool(look.random() < 0.5)
    speed = float(look.uniform(*WALK_MPS))
    x, y = at
    if not walks:
        return person(key, (0.0, x, y), mirror=mirror, body=replace(body, facing_deg=facing))
    vx, vy = speed * math.cos(math.radians(facing)), speed * math.sin(math.radians(facing))
    return person(key, (0.0, x - vx, y - vy), (2.0, x + vx, y + vy), mirror=mirror, body=body)


def make_world(
    rng: np.random.Generator,
    look: np.random.Generator,
    band: tuple[float, float],
    hfov_deg: float,
    key: str = "",
    seed: int = 0,
) -> World:
    """The robot at the origin; a person about ``band`` away (in the camera's view), up to two
    more elsewhere, and sometimes a bin in front; at time 1 s. ``rng`` places them, ``look``
    draws their pose, ``key`` and ``seed`` their bodies."""
    half = math.radians(hfov_deg / 2) * 0.8
    radius = Target("p", "person", "person", 1.7, ((0.0, 0.0, 0.0),)).radius
    first = float(rng.uniform(*band)) + radius  # the centre's range: the front's plus a radius
    placed: list[tuple[float, float]] = [(first, float(rng.uniform(-half, half)))]
    for _ in range(int(rng.integers(0, 3))):
        r = float(rng.uniform(1.0, band[1] + 3.0))
        if rng.random() < 0.5:
            # overlapping the first person in the image: in front of or behind them, off by
            # a third to two thirds of a person's width
            shift = float(rng.uniform(0.2, 0.45)) * float(rng.choice((-1, 1)))
            b = placed[0][1] + shift / min(r, first)
            if abs(r - first) < 0.6:
                continue
        else:
            b = float(rng.uniform(-half, half))
        placed.append((r, b))
    targets = []
    for i, (r, b) in enumerate(placed):
        flat = math.sqrt(max(r * r - 0.25**2, 0.1))  # a 3D distance r to mid-height
        at = (flat * math.cos(b), flat * math.sin(b))
        mirror = bool(rng.integers(0, 2))
        targets.append(_person(f"{key}p{i}", seed, look, at, mirror))
    obstacles = []
    if rng.random() < 0.4 and first > 1.8:
        # a low bin between the robot and the first person, hiding their legs
        r = float(rng.uniform(1.0, first - 0.7))
        b = placed[0][1] + float(rng.uniform(-0.08, 0.08))
        obstacles.append(Obstacle(r * math.cos(b), r * math.sin(b), 0.25))
    return World(Robot(), obstacles=obstacles, targets=targets, t=1.0)


@dataclass(frozen=True, slots=True)
class Frame:
    """One world as the benchmark sees it: ``world`` as drawn (people flat in the simple
    world), the ``colour`` image the detector gets, the ``depth`` (metres, NaN: none) and
    the ``truth`` depth it was made from (no faults)."""

    world: World
    colour: Image
    depth: Depth
    truth: Depth


class Camera:
    """The simulator's camera in one world kind (module docstring); each fault drawn from its
    own stream, as the simulator's: depth ``[seed, 1]``, colour ``[seed, 2]``."""

    def __init__(self, world: str, seed: int) -> None:
        self.settings = settings_for(world)
        s = self.settings
        self.spec = CameraSpec(s.width, s.height, HFOV_DEG, s.camera_height_m)
        self.noise: DepthNoise = depth_noise(s)
        self.colour_faults: ColourFaults = colour_faults_of(s)
        self.depth_rng = np.random.default_rng([seed, 1])
        self.colour_rng = np.random.default_rng([seed, 2])

    def frame(self, built: World) -> Frame:
        world = world_for(self.settings, built)
        clean = render(world, self.spec)
        truth = mirror_reads(
            world, self.spec, render_depth(world, self.spec), self.noise.mirror_scale
        )
        depth = apply(truth, clean, self.noise, self.depth_rng)
        return Frame(world, self._colour(clean), depth, truth)

    def _colour(self, clean: Image) -> Image:
        f = self.colour_faults
        if not f.on:
            return clean
        rng = self.colour_rng
        rate = float(rng.uniform(-TURN_RATE, TURN_RATE))
        exposure = Exposure(f, float(rng.uniform(-math.pi, math.pi)))
        exposure.gain(0.0, -rate * TURN_S, rng)  # adapted to where it looked before the turn
        return colour_faults(clean, exposure, TURN_S, 0.0, rate, self.spec.focal_px, rng)


@dataclass(frozen=True, slots=True)
class Truth:
    """One target's truths: ``box`` its true visible box (x0, y0, x1, y1, end-exclusive
    pixels); ``point`` the point a depth camera observes on it (targets_in_camera: the
    body's surface on its axis at half its height; a card's front face), optical frame, and
    ``face_h`` that point's horizontal range hypot(x, z), ``face`` its 3D distance; ``centre``
    the distance to its axis at half its height (the box height's truth); ``surface`` the
    horizontal range to the nearest point of the circle the laser sees; ``index`` its index
    in the owner image (simworld/depth.py ``owners``)."""

    box: tuple[int, int, int, int]
    point: tuple[float, float, float]
    face_h: float
    face: float
    centre: float
    surface: float
    index: int = -1


def truths(world: World, spec: CameraSpec, min_visible: float = MIN_VISIBLE) -> dict[str, Truth]:
    """Each target the camera sees (more than ``min_visible`` of it), by id."""
    return seen(world, spec, min_visible)[0]


def seen(
    world: World, spec: CameraSpec, min_visible: float = MIN_VISIBLE
) -> tuple[dict[str, Truth], npt.NDArray[np.int32]]:
    """:func:`truths`, and which drawn thing owns each pixel (``Truth.index``; -1: none)."""
    owner, placed = owners(world, spec)
    by_id = {
        world.targets[p.target].id: (k, p) for k, p in enumerate(placed) if p.target is not None
    }
    out = {}
    for tid, _name, x, y, z in targets_in_camera(world, spec, min_visible=min_visible):
        k, p = by_id[tid]
        ys, xs = np.nonzero(owner == k)
        box = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
        drop = spec.height_m - p.height_m / 2
        tg = world.targets[p.target] if p.target is not None else None
        radius = tg.radius if tg is not None else 0.0
        out[tid] = Truth(
            box=box,
            point=(x, y, z),
            face_h=math.hypot(x, z),
            face=math.sqrt(x * x + y * y + z * z),
            centre=math.sqrt(p.z * p.z + p.lateral * p.lateral + drop * drop),
            surface=math.hypot(p.z, p.lateral) - radius,
            index=k,
        )
    return out, owner


def laser_scan(world: World, rng: np.random.Generator) -> Any:
    """A scan of ``world`` by the simulator's laser (its targets the circles of their radius)."""
    from common.messages import Header, LaserScan
    from simworld.laser import LaserSpec, cast

    spec = LaserSpec()
    r = world.robot
    ranges = cast((r.x, r.y, r.theta), world.circles(), spec, rng)
    return LaserScan(
        header=Header(stamp_ns=1, seq=0, frame_id="laser", source="bench"),
        angle_min=spec.angle_min,
        angle_increment=spec.angle_increment,
        range_min=spec.range_min,
        range_max=spec.range_max,
        ranges=ranges,
    )


def boxes_of(truth: dict[str, Truth]) -> tuple[list[str], npt.NDArray[np.float64]]:
    """The ids and true visible boxes (n, 4) of ``truth``, in one order."""
    ids = list(truth)
    return ids, np.array([truth[t].box for t in ids], np.float64).reshape(-1, 4)
