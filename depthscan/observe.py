"""What one depth frame shows the controller: floor, obstacles, drop-offs and holes, and the
virtual scan made of them (issue 38's rules). Pure numpy: no bus, no clock.

Each sample (depthscan/frame.py) is back-projected with the image's
intrinsics and placed in the robot's base frame by the camera's mounting (perception/depth.py
``to_robot``: forward, left, up from the floor under the base's centre). By its height ``up``:
    floor      ``|up| <= floor_margin_m``
    drop       ``up < -floor_margin_m``: below the floor (a stairwell, a kerb down)
    obstacle   ``floor_margin_m < up <= max_height_m``; and every pixel that reads "too close"
               (32FC1 ``-inf``, REP 117), placed at the frame's minimum range along its ray
    overhead   ``up > max_height_m``: passes over the robot, and shows nothing of the floor
Each column is then read from the bottom of the image up (:func:`observe`): clear only as far
as its run of floor goes. A ray of the scan reads the nearest obstacle, drop-off edge or end
of a column's floor run in its direction; in view with nothing known there, the camera's
minimum range (blocked). The frame's floor, hazards and unknown stretches go on to the
depth scan stage's memory (depthscan/local_map.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import Header, LaserScan
from depthscan.frame import (
    MIN_NEAR_M,
    UNSTATED_RANGE_MAX_M,
    Samples,
    ScanParams,
    sample_metres,
    usable,
)
from perception import Intrinsics, Mounting, to_robot


def virtual_scan(
    depth: npt.NDArray[np.float32],
    intr: Intrinsics,
    mount: Mounting,
    params: ScanParams,
    header: Header,
    range_max_m: float = 0.0,
    range_min_m: float = 0.0,
) -> LaserScan:
    """The virtual scan of ``depth`` ((h, w) metres, NaN = no reading, ``-inf`` = too close)
    seen through ``intr``: :func:`observe`'s scan of its samples."""
    h, w = depth.shape
    if (w, h) != (intr.width, intr.height):
        raise ValueError(f"a {w}x{h} depth image with intrinsics for {intr.width}x{intr.height}")
    samples = sample_metres(depth, params.stride_px)
    return observe(samples, intr, mount, params, header, range_max_m, range_min_m).scan


# What a sample shows, by its height in the robot's frame (see the module's docstring).
NONE, FLOOR, DROP, SOLID, OVERHEAD = 0, 1, 2, 3, 4
# How a column's run of floor from the bottom of the image ends.
RUN_OPEN, RUN_SOLID, RUN_DROP, RUN_GAP = 0, 1, 2, 3


@dataclass(frozen=True, slots=True)
class Observation:
    """What one depth frame shows, in the robot's frame at the frame's capture (metres,
    forward and left of the base's centre): the virtual ``scan``; the ``floor`` points seen
    (k, 2), the ``hazards`` (k, 2) seen (obstacles, the last floor before a drop-off, "too
    close"), and ``unknown`` (k, 2): points along the stretches of floor a column should
    have seen and did not (a hole between two floor readings, no floor where the camera's
    height says it must be), where something could hide. The local map
    (depthscan/local_map.py) remembers them."""

    scan: LaserScan
    floor: npt.NDArray[np.float64]
    hazards: npt.NDArray[np.float64]
    unknown: npt.NDArray[np.float64]


def _runs(
    kind: npt.NDArray[np.int8], hole_rows: int
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Each column's run of floor from its first row (``kind`` (rows, columns), rows nearest
    first): the last floor row of the run (-1: none), how the run ends (``RUN_*``) and the
    row where it ends (the breaking sample, or a hole's first row). The run goes on over
    floor and over holes (no reading, or overhead) shorter than ``hole_rows``; it ends at an
    obstacle, a drop-off (a reading below the floor) or a hole of ``hole_rows`` rows."""
    rows, cols = kind.shape
    last = np.full(cols, -1, np.intp)
    end = np.full(cols, RUN_OPEN, np.intp)
    at = np.full(cols, rows, np.intp)
    hole = np.zeros(cols, np.intp)
    active = np.ones(cols, np.bool_)
    for r in range(rows):
        k = kind[r]
        floor = active & (k == FLOOR)
        last[floor] = r
        hole[floor] = 0
        empty = active & ((k == NONE) | (k == OVERHEAD))
        hole[empty] += 1
        gap = empty & (hole >= hole_rows)
        end[gap], at[gap] = RUN_GAP, r - hole_rows + 1
        for what, ending in ((SOLID, RUN_SOLID), (DROP, RUN_DROP)):
            hit = active & (k == what)
            end[hit], at[hit] = ending, r
        active &= ~(gap | (active & ((k == SOLID) | (k == DROP))))
        if not active.any():
            break
    return last, end, at


def _edge_band(
    filled: npt.NDArray[np.bool_], range_m: npt.NDArray[np.float64], width: int
) -> npt.NDArray[np.float64]:
    """For each column, the nearest ``range_m`` of a ``filled`` column within ``width``
    columns of it (+inf: none)."""
    near = np.where(filled, range_m, np.inf)
    out = near.copy()
    for k in range(1, width + 1):
        out[k:] = np.minimum(out[k:], near[:-k])
        out[:-k] = np.minimum(out[:-k], near[k:])
    return out


def observe(
    samples: Samples,
    intr: Intrinsics,
    mount: Mounting,
    params: ScanParams,
    header: Header,
    range_max_m: float = 0.0,
    range_min_m: float = 0.0,
) -> Observation:
    """What a depth image's ``samples``, seen through ``intr`` by a camera mounted at
    ``mount``, show (:class:`Observation`); its scan is stamped with ``header`` (the depth
    frame's: its capture time). ``range_max_m``, ``range_min_m``: the camera's stated range
    (0: not stated).

    Each sampled column is read from the bottom of the image up, the floor nearest first:
    the floor is known clear as far as its run of floor readings goes. The run ends at

    - an obstacle: the column is clear up to it;
    - a reading below the floor (a drop-off): the edge is at the last floor seen, a hazard
      there; with no floor seen before it, the edge is nearer than the camera sees the
      floor: blocked at the nearest range it could be (the camera's minimum range);
    - a hole of no readings ``hole_px`` tall or more: clear up to the last floor before it;
      the stretch from there to the next floor reading is unknown (a dark thing can stand
      there); no floor at all where the camera's height says it must be seen is unknown from
      the camera's minimum range on, and blocks there, unless a column within
      ``edge_band_px`` shows a thing filling the bottom of the image: the hole is then that
      thing's edge (a stereo camera's band of no readings beside a near object), blocking at
      its range.

    ValueError when the mounting's height is unknown (see :func:`usable`).
    """
    if not usable(mount):
        raise ValueError("the camera's height above the floor is unknown (mount_height_m 0)")
    # Rows nearest first: the bottom of the image sees the nearest floor.
    order = np.argsort(-samples.v, kind="stable")
    v = samples.v[order]
    u = samples.u
    zs = samples.z[order]
    close = samples.too_close[order]
    rx = (u + 0.5 - intr.cx) / intr.fx  # (cols,) x / z of each column's ray
    ry = (v + 0.5 - intr.cy) / intr.fy  # (rows,) y / z (down) of each row's ray
    shape = zs.shape
    near_z = max(range_min_m, MIN_NEAR_M)
    z = np.where(close, near_z, zs)
    seen = np.isfinite(z)
    zz = np.where(seen, z, 0.0)
    fwd, left, up = to_robot(
        np.broadcast_to(rx[None, :], shape) * zz,  # type: ignore[arg-type]
        np.broadcast_to(ry[:, None], shape) * zz,  # type: ignore[arg-type]
        zz,  # type: ignore[arg-type]
        mount,
    )
    margin = params.floor_margin_m
    kind = np.full(shape, NONE, np.int8)
    kind[seen & (up > params.max_height_m)] = OVERHEAD
    kind[seen & (up > margin) & (up <= params.max_height_m)] = SOLID
    kind[seen & (up < -margin)] = DROP
    kind[seen & (np.abs(up) <= margin)] = FLOOR
    kind[close] = SOLID
    rng = np.hypot(fwd, left)

    n = max(1, round(360.0 / params.resolution_deg))
    increment = math.tau / n

    def bin_of(angle: npt.NDArray[np.float64]) -> npt.NDArray[np.intp]:
        out: npt.NDArray[np.intp] = np.floor((angle + math.pi) / increment).astype(np.intp) % n
        return out

    cols = np.arange(len(u))

    def ground(
        col: npt.NDArray[np.intp], zc: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(forward, left) of the floor-level point ``zc`` along column ``col``'s ray."""
        f, lft, _ = to_robot(rx[col] * zc, np.zeros_like(zc), zc, mount)  # type: ignore[arg-type]
        return f, lft

    # In view: the directions the sampled columns look along (from the camera's yaw).
    nf, nl = ground(cols, np.full(len(u), near_z))
    near_rng = np.hypot(nf, nl)  # each column's nearest range at which it could see a thing
    looks = bin_of(np.arctan2(nl, nf))
    ranges = np.full(n, np.nan, np.float64)
    ranges[looks] = np.inf
    solid = kind == SOLID
    np.fmin.at(ranges, bin_of(np.arctan2(left[solid], fwd[solid])), rng[solid])

    hole_rows = max(1, math.ceil(params.hole_px / params.stride_px))
    below = ry > 0  # rows that can see the floor at all
    last, end, at = _runs(kind[below], hole_rows)
    has_floor = last >= 0
    colf = cols[has_floor]
    reach = np.full(len(u), np.nan)
    reach[colf] = rng[last[colf], colf]
    # Every column is clear no farther than the end of its run of floor.
    np.fmin.at(ranges, looks[has_floor], reach[has_floor])
    # No floor before the run ended on a drop or a hole (or no row below the horizon at
    # all): blocked at the nearest range something could be.
    blind = ~has_floor & ((end == RUN_DROP) | (end == RUN_GAP) | (end == RUN_OPEN))
    if not below.any():
        blind[:] = True
    # Except beside a thing that fills the bottom of the image: a stereo camera reads nothing
    # in a band along a near object's edge (what one eye sees and the other does not); there
    # the hole is taken as that object's edge, at its range.
    # A column filled from the bottom by a thing is clear up to it (its own points may fall in
    # other rays than the column's, for a camera off the base's centre).
    filled = ~has_floor & (end == RUN_SOLID)
    first = rng[np.minimum(at, len(v) - 1), cols]
    np.fmin.at(ranges, looks[filled], first[filled])
    band = _edge_band(filled, first, math.ceil(params.edge_band_px / params.stride_px))
    edged = blind & np.isfinite(band)
    np.fmin.at(ranges, looks[edged], band[edged])
    blind &= ~edged
    np.fmin.at(ranges, looks[blind], near_rng[blind])
    ranges[np.isposinf(ranges)] = near_rng.min()  # in view, nothing seen that way

    # Hazards: obstacles, and the edge (the last floor seen) before a drop-off.
    edge = has_floor & (end == RUN_DROP)
    ce = cols[edge]
    hazards = np.concatenate([
        np.stack([fwd[solid], left[solid]], axis=1),
        np.stack([fwd[last[ce], ce], left[last[ce], ce]], axis=1),
    ])  # fmt: skip
    # Unknown stretches: from the last floor seen (or the nearest range) to the next floor
    # reading after the hole (or, with none, as far as the floor should have been seen).
    ub = np.flatnonzero(below)
    z_floor = np.where(below, mount.height_m / np.where(below, ry, 1.0), np.inf)  # per row
    unknown = []
    for c in np.flatnonzero(((end == RUN_GAP) & has_floor) | blind):
        z0 = zs[last[c], c] if last[c] >= 0 else near_z
        after = np.flatnonzero(kind[below][at[c] :, c] == FLOOR)
        if after.size:
            z1 = zs[ub[at[c] + after[0]], c]
        elif last[c] >= 0:
            continue  # the floor ends here: not clear beyond, and nothing known to hide
        else:
            z1 = z_floor[ub[min(at[c] + hole_rows, len(ub)) - 1]] if ub.size else near_z
        z1 = min(z1, z0 + params.unknown_span_m)
        if z1 > z0:
            zc = np.arange(z0, z1, params.unknown_step_m)
            unknown.append(np.stack(ground(np.full(len(zc), c), zc), axis=1))
    floor = kind == FLOOR
    scan = LaserScan(
        header=header,
        angle_min=-math.pi + increment / 2,  # each ray at its bin's centre
        angle_increment=increment,
        range_min=0.0,
        range_max=range_max_m if range_max_m > 0 else UNSTATED_RANGE_MAX_M,
        ranges=ranges.astype(np.float32),
    )
    return Observation(
        scan,
        np.stack([fwd[floor], left[floor]], axis=1),
        hazards,
        np.concatenate(unknown) if unknown else np.zeros((0, 2)),
    )
