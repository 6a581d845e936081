"""The way ahead: whether the controller may drive forward this tick, judged on every obstacle
source (the laser's scan, the depth cameras' virtual scan, what the depth cameras' map
remembers round the robot), and how fast while part of the corridor ahead was never seen.
Pure: no bus, no clock; services/controller/policy.py asks it on every tick.

The rule of every mode, for every source: nothing within the safety distance plus the room to
brake in the sector and corridor ahead. A source the settings require (``obstacle_sources``)
that is missing or stale means no forward motion; one not required is obeyed when it comes (the
laser with ``no_laser``, the depth cameras on a robot that needs a laser).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from common.messages import LaserScan
from services.controller.contract import DEPTH_SOURCE, ControllerSettings
from services.controller.geometry import sector_clearance, sector_range


@dataclass(frozen=True, slots=True)
class Obstacles:
    """One obstacle source at this tick: its scan (None when missing or stale), whether the
    settings require it for forward motion, the reason when it is missing, and the room the
    robot needs to stop on what it shows (braking plus the distance covered while it aged)."""

    name: str
    scan: LaserScan | None
    required: bool
    missing: str
    stopping_m: float
    known_m: float = math.inf


class ObstacleInputs(Protocol):
    """What :func:`tick_sources` reads of a tick's inputs (policy.py's ``Inputs``)."""

    @property
    def scan(self) -> LaserScan | None: ...
    @property
    def scan_age_s(self) -> float: ...
    @property
    def depth(self) -> LaserScan | None: ...
    @property
    def depth_age_s(self) -> float: ...
    @property
    def depth_missing(self) -> str: ...
    @property
    def depth_remembered(self) -> LaserScan | None: ...
    @property
    def depth_known_m(self) -> float: ...


def tick_sources(s: ControllerSettings, inp: ObstacleInputs, speed: float) -> tuple[Obstacles, ...]:
    """This tick's sources, the laser's first: each scan only while fresh (``scan_timeout_s``,
    ``depth_timeout_s``), each with the room the robot needs to stop from ``speed`` (the
    fastest this tick may command), braking at the acceleration limit, plus the distance
    covered while its scan aged and the next tick comes."""
    scan = inp.scan if inp.scan_age_s <= s.scan_timeout_s else None
    depth = inp.depth if inp.depth_age_s <= s.depth_timeout_s else None
    braking = speed * speed / (2 * s.max_linear_accel)

    def stopping(age_s: float) -> float:
        return braking + speed * (age_s + 1.0 / s.control_rate_hz)

    return (
        Obstacles(
            "laser",
            scan,
            s.laser_required,
            "no recent laser scan",
            stopping(inp.scan_age_s if scan is not None else 0.0),
        ),
        Obstacles(
            "depth",
            depth,
            DEPTH_SOURCE in s.obstacle_sources,
            inp.depth_missing if inp.depth is None else "no recent depth",
            stopping(inp.depth_age_s if depth is not None else 0.0),
            inp.depth_known_m,
        ),
        Obstacles(
            "remembered",
            inp.depth_remembered if depth is not None else None,
            False,
            "",
            stopping(inp.depth_age_s if depth is not None else 0.0),
        ),
    )


def blocked(obstacles: tuple[Obstacles, ...], s: ControllerSettings) -> str | None:
    """Why the robot may not drive forward now, or None when the way ahead is known clear
    (the module's rule)."""
    for source in obstacles:
        if source.scan is None:
            if source.required:
                return source.missing
            continue
        by = "" if source.name == "laser" else f" ({source.name})"
        if math.isnan(sector_range(source.scan, 0.0, s.sector_width_deg, unseen=math.nan)):
            # No ray of the sector ahead holds a reading: blocked, and said so, not as an
            # obstacle at 0.00 m that nobody can find (issue 39).
            return f"nothing seen straight ahead{by}"
        clearance = sector_clearance(source.scan, s.sector_width_deg, s.robot_width_m / 2)
        if clearance <= s.safety_distance_m + source.stopping_m:
            return f"obstacle at {clearance:.2f} m{by}"
    return None


def creep(
    obstacles: tuple[Obstacles, ...], s: ControllerSettings, linear: float, reason: str
) -> tuple[float, str]:
    """``linear`` no faster than ``depth_creep_speed`` while a required obstacle source
    knows the corridor ahead less far than the robot needs to stop (part of it never
    seen: the depth camera's blind zone at start-up), with the reason said."""
    for source in obstacles:
        if not (source.required and source.scan is not None) or linear <= 0:
            continue
        short = source.known_m <= s.safety_distance_m + source.stopping_m
        if short and linear > s.depth_creep_speed:
            return s.depth_creep_speed, (
                f"{reason}; creeping: the floor is known only {source.known_m:.2f} m "
                f"ahead ({source.name})"
            )
    return linear, reason


def known_clear(obstacles: tuple[Obstacles, ...], s: ControllerSettings) -> bool:
    """Whether some obstacle source is fresh and none shows the way ahead blocked: what
    driving on towards a target not seen needs (``no_laser`` or not)."""
    seen = any(source.scan is not None for source in obstacles)
    return seen and blocked(obstacles, s) is None
