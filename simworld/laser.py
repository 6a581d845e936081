"""A planar laser scanner: rays cast against round obstacles, vectorised. Pure.

The scan is one plane, ``height_m`` above the floor: the caller passes the circles that cut it
(simworld/world.py ``World.laser_circles``: nothing lower, no glass). A drop-off in the
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
) -> npt.NDArray[np.float32]:
    """Ranges (rays,) from ``pose`` (x, y, theta) to the nearest circle (x, y, r) per ray."""
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
    if rng is not None and spec.noise_std_m > 0:
        ranges = ranges + rng.normal(0.0, spec.noise_std_m, spec.rays)
    ranges = np.where(ranges > spec.range_max, np.inf, ranges)
    out: npt.NDArray[np.float32] = np.maximum(ranges, spec.range_min).astype(np.float32)
    return out
