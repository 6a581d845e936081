"""How hard the simulated world is (``sim.world``), and the camera faults that run in it.

The rule: ``sim.world = "hard"`` (the default) runs every newer fault with its own setting
(``depth_bias_k``, ``depth_flying_share``, ``depth_mirror_scale``,
``depth_noise_in_disparity``, ``colour_*``; each set to 0, false, or 1 for the mirror's scale,
turns that one off). ``"simple"`` is today's world and camera:
it sets those settings off (contract.SIMPLE_FAULTS) whatever the config says, keeps the older
``depth_*`` settings (today's noise, holes, dropout), and draws the people flat
(:func:`world_for`). The start-up log's :func:`world_line` says which world and faults run.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Any

import numpy as np

from common.images import Image
from services.sim.cameras import SimCamera
from services.sim.contract import SIMPLE_FAULTS, SimSettings, SimWorld
from simworld.depth import Depth, DepthNoise, apply, render_depth
from simworld.faults import ColourFaults, Exposure, colour_faults, mirror_reads
from simworld.world import World, flat_world


def in_effect(s: SimSettings) -> SimSettings:
    """``s`` as the simulator runs it: with ``world = "simple"``, every newer fault off."""
    off: dict[str, Any] = dict(SIMPLE_FAULTS)
    return dataclasses.replace(s, **off) if s.world is SimWorld.SIMPLE else s


def world_for(s: SimSettings, world: World) -> World:
    """The world the simulator runs: the scenario's ``world`` as built ("hard"), or today's
    ("simple": people drawn flat). The one place the world's hardness changes the world."""
    if s.world is SimWorld.SIMPLE:
        return flat_world(world)  # every person the flat card of before
    return world


def depth_noise(s: SimSettings) -> DepthNoise:
    """The depth camera's faults, from the ``sim.depth_*`` settings in effect."""
    e = in_effect(s)
    return DepthNoise(
        range_min_m=e.depth_range_min_m,
        range_max_m=e.depth_range_max_m,
        noise_k=e.depth_noise_k,
        noise_corr_px=e.depth_noise_corr_px,
        edge_px=e.depth_edge_px,
        edge_jump=e.depth_edge_jump,
        dark_level=e.depth_dark_level,
        dark_dropout=e.depth_dark_dropout,
        dropout=e.depth_dropout,
        bias_k=e.depth_bias_k,
        flying_share=e.depth_flying_share,
        mirror_scale=e.depth_mirror_scale,
        in_disparity=e.depth_noise_in_disparity,
    )


def colour_faults_of(s: SimSettings) -> ColourFaults:
    """The colour camera's faults, from the ``sim.colour_*`` settings in effect."""
    e = in_effect(s)
    return ColourFaults(
        exposure_s=e.colour_exposure_ms / 1000.0,
        light_change=e.colour_light_change,
        light_tau_s=e.colour_light_tau_s,
        drift=e.colour_drift,
        drift_tau_s=e.colour_drift_tau_s,
    )


def world_line(s: SimSettings) -> str:
    """One line for the log: ``world=<hard|simple> faults=<name:value,...|none>``, the newer
    fault settings in effect that are on (the depth camera's only with ``sim.depth``; see
    :func:`parse_world_line`)."""
    e = in_effect(s)
    on = [
        f"{name}:{getattr(e, name):g}"
        for name, off in SIMPLE_FAULTS.items()
        if getattr(e, name) != off and (e.depth or not name.startswith("depth_"))
    ]
    return f"world={s.world} faults={','.join(on) or 'none'}"


_LINE = re.compile(r"world=(\w+) faults=(\S+)")


def parse_world_line(line: str) -> tuple[str, dict[str, float]] | None:
    """The world and the faults (name -> value) of a log line holding :func:`world_line`'s
    text; None when it holds none."""
    m = _LINE.search(line)
    if m is None:
        return None
    faults = m.group(2)
    pairs = [] if faults == "none" else [f.split(":", 1) for f in faults.split(",")]
    return m.group(1), {name: float(value) for name, value in pairs}


class Faults:
    """The cameras' faults over a run, each drawn from its own stream seeded by ``sim.seed``
    (so the laser's noise is the same with depth or without, and depth's with colour faults or
    without): depth ``[seed, 1]``, colour ``[seed, 2]`` (whose first draw is the bearing of
    the light, world frame). Each camera's exposure is its own."""

    def __init__(self, s: SimSettings, cameras: list[SimCamera]) -> None:
        self.depth = depth_noise(s) if s.depth else None
        self.depth_rng = np.random.default_rng([s.seed, 1])
        colour = colour_faults_of(s)
        self.colour_rng = np.random.default_rng([s.seed, 2])
        self.exposures: dict[str, Exposure] = {}
        if colour.on:
            bearing = float(self.colour_rng.uniform(-math.pi, math.pi))
            self.exposures = {c.name: Exposure(colour, bearing) for c in cameras}

    def colour(self, camera: SimCamera, image: Image, world: World, t: float) -> Image:
        """``camera``'s rendered ``image`` as it delivers it at time ``t`` (s), the robot
        turning at its current yaw rate: ``image`` itself with no colour faults."""
        exposure = self.exposures.get(camera.name)
        if exposure is None:
            return image
        r, spec = world.robot, camera.spec
        heading = r.theta + math.radians(spec.mount_yaw_deg)
        return colour_faults(image, exposure, t, heading, r.w, spec.focal_px, self.colour_rng)

    def depth_image(self, camera: SimCamera, image: Image, world: World) -> Depth:
        """``camera``'s depth image of ``world`` (metres, NaN = no reading), its faults drawn
        against its clean colour ``image``; needs ``sim.depth``."""
        if self.depth is None:
            raise RuntimeError("a depth image without sim.depth")
        spec = camera.spec
        truth = mirror_reads(world, spec, render_depth(world, spec), self.depth.mirror_scale)
        return apply(truth, image, self.depth, self.depth_rng)
