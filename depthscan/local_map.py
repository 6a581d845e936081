"""The depth cameras' short memory: a small rolling map of the floor round the robot. Pure:
no bus, no clock (times are handed in).

A depth camera sees the floor only from some way ahead (a level camera 0.6 m up with a 60 deg
view: from 1.39 m), so a low box or a kerb seen on the way slips out of view as the robot
nears it. Each frame's :class:`~depthscan.observe.Observation` is written into a
grid fixed to the odometry frame, placed by the robot's pose when the frame was captured:

    FREE     floor seen there
    HAZARD   an obstacle or a drop-off's edge seen there
    UNKNOWN  a stretch where floor should have been seen and was not (a hole, a dark thing)
    UNSEEN   never seen (every cell at start-up, and those the window rolls in)

A cell keeps what it was last seen as: a hazard stays a hazard until floor is seen in it (a
later frame that sees floor there and no hazard), so a thing that enters the blind zone stays
an obstacle. In one frame a hazard wins over unknown, and unknown over floor. The cells under
the robot's own footprint are floor (the robot stands on them).

The pose comes from :class:`~common.odometry.Odometry`: the controller's own commands,
integrated. A base that does not move as commanded (a wheel slipping, pushed by hand) moves
the memory wrongly; one that moves less than commanded brings remembered things nearer,
which errs towards stopping.

What the controller reads (:meth:`LocalMap.read`): the HAZARD and UNKNOWN cells as a scan of
ranges round the robot (merged with the cameras' own virtual scans and judged by the same
rules) and how far straight ahead the corridor is known (no UNSEEN cell): beyond that the
robot may only creep (``depth_creep_speed``).
"""

from __future__ import annotations

import io
import math
import zipfile
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import Header, LaserScan
from common.unicycle import Pose
from depthscan.observe import Observation

UNSEEN, FREE, UNKNOWN, HAZARD = 0, 1, 2, 3


@dataclass(frozen=True, slots=True)
class MapParams:
    """The map's size and how it is read (the controller's ``depth_memory_*`` settings)."""

    resolution_m: float = 0.05
    size_m: float = 8.0
    corridor_half_width_m: float = 0.3
    footprint_half_m: float = 0.3
    known_ahead_m: float = 3.0


def _to_odom(pose: Pose, pts: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Robot-frame points (k, 2) as odometry-frame points at ``pose``."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    out: npt.NDArray[np.float64] = np.empty_like(pts)
    out[:, 0] = x + c * pts[:, 0] - s * pts[:, 1]
    out[:, 1] = y + s * pts[:, 0] + c * pts[:, 1]
    return out


def _to_robot(pose: Pose, pts: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Odometry-frame points (k, 2) in the robot's frame at ``pose``."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    dx, dy = pts[:, 0] - x, pts[:, 1] - y
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)


@dataclass(frozen=True, slots=True)
class Remembered:
    """What the map holds round the robot now: ``scan`` of its HAZARD and UNKNOWN cells
    (each ray the nearest such cell's near side; +inf where none), and ``known_m``: how far
    ahead the corridor is known (seen at least once), from the base's centre."""

    scan: LaserScan
    known_m: float


class LocalMap:
    """The rolling grid (see the module's docstring). Not thread-safe: its owner locks."""

    def __init__(self, params: MapParams, resolution_deg: float = 1.0) -> None:
        self.p = params
        self.n = max(8, round(params.size_m / params.resolution_m))
        self.grid = np.full((self.n, self.n), UNSEEN, np.uint8)
        self.origin = np.array([-self.n / 2, -self.n / 2]) * params.resolution_m
        self.bins = max(1, round(360.0 / resolution_deg))
        res = params.resolution_m
        # The corridor ahead sampled at half a cell: rows by distance ahead, columns across.
        xs = np.arange(0.0, params.known_ahead_m + res, res / 2)
        ys = np.arange(-params.corridor_half_width_m, params.corridor_half_width_m + 1e-9, res / 2)
        self._corridor_x = xs
        self._corridor = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
        fp = np.arange(-params.footprint_half_m, params.footprint_half_m + 1e-9, res / 2)
        self._footprint = np.stack(np.meshgrid(fp, fp, indexing="ij"), axis=-1).reshape(-1, 2)

    def _cells(
        self, odom: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.bool_]]:
        """Row (x) and column (y) indices of odometry points, and which are on the grid."""
        ij = np.floor((odom - self.origin) / self.p.resolution_m).astype(np.intp)
        inside: npt.NDArray[np.bool_] = np.asarray(((ij >= 0) & (ij < self.n)).all(axis=1))
        return ij[:, 0], ij[:, 1], inside

    def follow(self, pose: Pose) -> None:
        """Roll the window by whole cells so that ``pose`` stays within a quarter of its
        middle; the cells rolled in are UNSEEN."""
        res, n = self.p.resolution_m, self.n
        centre = self.origin + n * res / 2
        off = (np.array(pose[:2]) - centre) / res
        shift = np.where(np.abs(off) > n / 4, np.round(off), 0).astype(np.intp)
        if not shift.any():
            return
        grid = np.full_like(self.grid, UNSEEN)
        sx, sy = int(shift[0]), int(shift[1])
        if abs(sx) < n and abs(sy) < n:
            src = self.grid[max(sx, 0) : n + min(sx, 0), max(sy, 0) : n + min(sy, 0)]
            grid[max(-sx, 0) : n + min(-sx, 0), max(-sy, 0) : n + min(-sy, 0)] = src
        self.grid = grid
        self.origin = self.origin + shift * res

    def _mark(self, pose: Pose, pts: npt.NDArray[np.float64], state: int) -> None:
        if len(pts) == 0:
            return
        i, j, inside = self._cells(_to_odom(pose, pts))
        self.grid[i[inside], j[inside]] = state

    def observe(self, seen: Observation, pose: Pose) -> bool:
        """Write a frame captured at ``pose``: its floor, then its unknown stretches, then
        its hazards (each over the one before). Whether a cell became a hazard or unknown
        that was not one before (what a crash must not lose)."""
        before = self.grid >= UNKNOWN
        self._mark(pose, seen.floor, FREE)
        if len(seen.unknown):
            i, j, inside = self._cells(_to_odom(pose, seen.unknown))
            i, j = i[inside], j[inside]
            keep = self.grid[i, j] != HAZARD
            self.grid[i[keep], j[keep]] = UNKNOWN
        self._mark(pose, seen.hazards, HAZARD)
        return bool(((self.grid >= UNKNOWN) & ~before).any())

    def dump(self, pose: Pose, saved_ns: int) -> bytes:
        """The map and the robot's ``pose`` in it at wall-clock ``saved_ns``, as bytes for
        :meth:`restore` (.npz)."""
        out = io.BytesIO()
        np.savez(out, grid=self.grid, origin=self.origin, pose=np.asarray(pose, np.float64),
                 resolution_m=np.float64(self.p.resolution_m),
                 saved_ns=np.int64(saved_ns))  # fmt: skip
        return out.getvalue()

    def restore(self, data: bytes) -> tuple[Pose, int, int]:
        """Take back a map :meth:`dump` wrote: what it remembered as hazards and unknown,
        not the floor it had seen (the robot may have moved a little since: a seen floor is
        seen again before it is driven on). The pose it was written with, the hazard and
        unknown cells restored, and when it was written (wall-clock ns). ValueError when
        ``data`` is not a map of this size."""
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as f:
                grid, origin = f["grid"], f["origin"]
                pose, res = f["pose"], float(f["resolution_m"])
                saved_ns = int(f["saved_ns"])
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"not a saved depth map ({exc})") from exc
        if grid.shape != self.grid.shape or grid.dtype != np.uint8 or res != self.p.resolution_m:
            raise ValueError(
                f"a {grid.shape} map of {res:g} m cells, not {self.grid.shape} of "
                f"{self.p.resolution_m:g} m (depth_memory_size_m or resolution changed)"
            )
        if (
            origin.shape != (2,)
            or pose.shape != (3,)
            or not (
                np.isfinite(origin).all() and np.isfinite(pose).all() and (grid <= HAZARD).all()
            )
        ):
            raise ValueError("a saved depth map with a bad origin, pose or cell")
        self.grid = np.where(grid == FREE, UNSEEN, grid).astype(np.uint8)
        self.origin = origin.astype(np.float64)
        kept = int(np.count_nonzero(self.grid))
        return (float(pose[0]), float(pose[1]), float(pose[2])), kept, saved_ns

    def stand(self, pose: Pose) -> None:
        """The robot stands at ``pose``: the floor under its footprint is free."""
        self.follow(pose)
        self._mark(pose, self._footprint, FREE)

    def read(self, pose: Pose, header: Header) -> Remembered:
        """What the robot at ``pose`` must know of the map (:class:`Remembered`)."""
        res = self.p.resolution_m
        i, j = np.nonzero(self.grid >= UNKNOWN)
        centres = self.origin + (np.stack([i, j], axis=1) + 0.5) * res
        local = _to_robot(pose, centres)
        increment = math.tau / self.bins
        ranges = np.full(self.bins, np.inf)  # nothing remembered that way
        if len(local):
            # The near side of each cell: its centre less half its diagonal.
            r = np.maximum(np.hypot(local[:, 0], local[:, 1]) - res * math.sqrt(0.5), 0.0)
            b = np.floor((np.arctan2(local[:, 1], local[:, 0]) + math.pi) / increment)
            np.fmin.at(ranges, b.astype(np.intp) % self.bins, r)
        ci, cj, inside = self._cells(_to_odom(pose, self._corridor))
        unseen = ~inside
        unseen[inside] = self.grid[ci[inside], cj[inside]] == UNSEEN
        rows = unseen.reshape(len(self._corridor_x), -1).any(axis=1)
        known = float(self._corridor_x[np.argmax(rows)]) - res if rows.any() else math.inf
        scan = LaserScan(
            header=header,
            angle_min=-math.pi + increment / 2,
            angle_increment=increment,
            range_min=0.0,
            range_max=self.p.size_m,
            ranges=ranges.astype(np.float32),
        )
        return Remembered(scan, max(known, 0.0))
