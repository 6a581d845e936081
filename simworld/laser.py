"""A planar laser scanner: rays cast against round obstacles and straight walls, vectorised. Pure.

The scan is one plane, ``height_m`` above the floor: the caller passes the circles and the wall
segments that cut it (simworld/world.py ``World.laser_circles`` and ``World.laser_walls``:
nothing lower, no glass). A drop-off in the
floor is below the plane, and no ray ever sees one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True, slots=True)
class LaserSpec:
    """Field of view and resolution; ranges beyond ``range_max`` read as +inf. ``height_m``:
    the scan plane's height above the floor (0.2 m: a 2D lidar on a small base)."""

    fov_deg: float = 270.0
    rays: int = 541
    range_min: float = 0.05
    range_max: float = 12.0
    noise_std_m: float = 0.01
    height_m: float = 0.2

    @property
    def angle_min(self) -> float:
        return float(-np.radians(self.fov_deg) / 2)

    @property
    def angle_increment(self) -> float:
        return float(np.radians(self.fov_deg) / (self.rays - 1))


def cast(
    pose: tuple[float, float, float],
    circles: npt.NDArray[np.float64],
    spec: LaserSpec,
    rng: np.random.Generator | None = None,
    segments: npt.NDArray[np.float64] | None = None,
) -> npt.NDArray[np.float32]:
    """Ranges (rays,) from ``pose`` (x, y, theta) to the nearest circle (x, y, r) or wall
    segment (x0, y0, x1, y1, ``segments``) per ray."""
    x, y, theta = pose
    angles = theta + spec.angle_min + spec.angle_increment * np.arange(spec.rays)
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (rays, 2) unit directions
    ranges = np.full(spec.rays, np.inf)
    if len(circles):
        oc = circles[:, :2] - np.array([x, y])  # (n, 2) robot -> centre
        b = d @ oc.T  # (rays, n) projection of the centre on each ray
        c = np.sum(oc**2, axis=1) - circles[:, 2] ** 2  # (n,)
        disc = b**2 - c
        hit = disc >= 0
        root = np.sqrt(np.where(hit, disc, 0.0))
        t_near = b - root
        # Inside a circle (c < 0) the exit point is the hit; otherwise the near side.
        t = np.where(c < 0, b + root, t_near)
        t = np.where(hit & (t > 0), t, np.inf)
        ranges = t.min(axis=1)
    if segments is not None and len(segments):
        ranges = np.minimum(ranges, _segment_ranges(x, y, d, segments))
    if rng is not None and spec.noise_std_m > 0:
        ranges = ranges + rng.normal(0.0, spec.noise_std_m, spec.rays)
    ranges = np.where(ranges > spec.range_max, np.inf, ranges)
    out: npt.NDArray[np.float32] = np.maximum(ranges, spec.range_min).astype(np.float32)
    return out


def _segment_ranges(
    x: float, y: float, d: npt.NDArray[np.float64], segments: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Per ray (unit directions ``d``, (rays, 2), from (x, y)) the distance to the nearest of
    the (x0, y0, x1, y1) ``segments``, inf where it meets none. The ray o + t d meets the
    segment a + s e where t = (p x e) / (d x e) and s = (p x d) / (d x e), p = a - o, x the
    2D cross product; a hit needs t > 0 and 0 <= s <= 1 (a ray along a segment meets none)."""
    a = segments[:, :2] - np.array([x, y])  # (n, 2) robot -> segment start
    e = segments[:, 2:] - segments[:, :2]  # (n, 2) start -> end
    denom = d[:, :1] * e[:, 1] - d[:, 1:] * e[:, 0]  # (rays, n)
    pe = a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]  # (n,)
    pd = a[:, 0] * d[:, 1:] - a[:, 1] * d[:, :1]  # (rays, n)
    ok = np.abs(denom) > 1e-12
    safe = np.where(ok, denom, 1.0)
    t, s = pe / safe, pd / safe
    hit = ok & (t > 0) & (s >= 0) & (s <= 1)
    out: npt.NDArray[np.float64] = np.where(hit, t, np.inf).min(axis=1)
    return out
