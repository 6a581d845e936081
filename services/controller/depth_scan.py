"""A virtual laser scan from a depth image, for a robot whose obstacles are seen by a depth
camera rather than a laser. Pure numpy: no bus, no clock.

Every ``stride_px``-th row and column of the depth image is taken (before anything is
converted: :func:`sample_frame`), back-projected with the image's intrinsics and placed in
the robot's base frame by the camera's mounting (perception/depth.py ``to_robot``: forward,
left, up from the floor under the base's centre). Each point is, by its height ``up``:
    floor      ``|up| <= floor_margin_m``
    drop-off   ``up < -floor_margin_m``: below the floor (a stairwell, a kerb down): an obstacle
    obstacle   ``floor_margin_m < up <= max_height_m``; and every pixel that reads "too close"
               (32FC1 ``-inf``, REP 117), placed at the frame's minimum range along its ray
    overhead   ``up > max_height_m``: passes over the robot, and shows nothing of the floor
The scan is in the ROBOT frame (REP 103: angle 0 forward, counter-clockwise positive), 360 deg
round, so that the controller's obstacle rules (services/controller/geometry.py) read it as
they read a laser's. "Clear only as far as seen": a bin's value is

    min(nearest obstacle or drop-off, farthest floor point seen)   in that direction, and no
          farther than where any sampled column's floor ends in it (a thin dark pole that
          stops one column is not made clear by the floor its neighbours see beyond)
    0     a direction in the camera's field of view (a sampled column looks along it) with no
          point at all, or only overhead ones: nothing known there, so blocked
    NaN   outside the field of view: the controller requires the fresh depth cameras together
          to see the whole sector ahead (:func:`depth_obstacles`)

so a dark wall with no readings reads as near as the floor seen in front of it, and an
obstacle nearer than the camera's minimum range hides the floor behind it and reads blocked.
A camera whose height above the floor is not known (``mount_height_m`` 0) cannot tell the
floor from an obstacle: it gives no virtual scan (``depth_no_mount``). A frame whose
intrinsics or mounting are implausible (:func:`implausible`) gives none either.

No separate check of the floor per frame: a height announced wrong by more than
``floor_margin_m`` puts the floor seen above the margin (an obstacle) or below it (a
drop-off), and one above ``max_height_m`` puts everything overhead (no point: blocked), so a
wrong height blocks wherever the floor is seen, while a check that the lower rows sit on the
floor would block a normal scene whose lower rows show a box, a ramp or a person.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import DepthFrame, Header, LaserScan
from perception import Intrinsics, Mounting, to_robot
from services.controller.geometry import wrap

#: The range a scan states when its depth image states none (DepthFrame.range_max_m 0).
UNSTATED_RANGE_MAX_M = 100.0
#: The nearest a camera that states no minimum range is taken to see (metres along its axis):
#: where a direction with no reading blocks. Above 0, so that it reads ahead of the base.
MIN_NEAR_M = 0.05


@dataclass(frozen=True, slots=True)
class ScanParams:
    """How a virtual scan is made (the controller's ``depth_*`` settings)."""

    floor_margin_m: float = 0.05
    max_height_m: float = 1.5
    stride_px: int = 4
    resolution_deg: float = 1.0
    hole_px: int = 12
    edge_band_px: int = 24
    unknown_span_m: float = 2.0
    unknown_step_m: float = 0.025


@dataclass(frozen=True, slots=True)
class Samples:
    """The pixels of a depth image a scan is made from: rows ``v`` and columns ``u`` (pixel
    indices), their depths ``z`` (len(v), len(u)) in metres (NaN: no reading) and where the
    camera said "too close" (``too_close``: 32FC1 ``-inf``)."""

    v: npt.NDArray[np.intp]
    u: npt.NDArray[np.intp]
    z: npt.NDArray[np.float64]
    too_close: npt.NDArray[np.bool_]


def _grid(
    width: int, height: int, stride: int
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The rows and columns taken: the middle of each stride."""
    return np.arange(stride // 2, height, stride), np.arange(stride // 2, width, stride)


def sample_metres(depth: npt.NDArray[np.float32], stride: int) -> Samples:
    """The samples of an image already in metres (perception/depth.py ``depth_metres``: NaN =
    no reading; ``-inf`` kept as "too close")."""
    h, w = depth.shape
    v, u = _grid(w, h, stride)
    z = depth[np.ix_(v, u)].astype(np.float64)
    too_close = np.isneginf(z)
    return Samples(v, u, np.where(np.isfinite(z) & (z > 0), z, np.nan), too_close)


def sample_frame(frame: DepthFrame, stride: int) -> Samples:
    """The samples of a depth frame, taken from its raw image before conversion (a 640x480
    image at stride 4 converts 19,200 pixels, not 307,200). No reading: 0, NaN, +inf, or
    outside the stated range; "too close": 32FC1 ``-inf`` (REP 117; 16UC1 cannot say it)."""
    v, u = _grid(frame.width, frame.height, stride)
    if frame.encoding == "16UC1":
        raw = np.frombuffer(frame.data, "<u2").reshape(frame.height, frame.width)
        z = raw[np.ix_(v, u)].astype(np.float64) / 1000.0
    else:
        raw32 = np.frombuffer(frame.data, "<f4").reshape(frame.height, frame.width)
        z = raw32[np.ix_(v, u)].astype(np.float64)
    too_close = np.isneginf(z)
    bad = ~np.isfinite(z) | (z <= 0) | (z < frame.range_min_m)
    if frame.range_max_m > 0:
        bad |= z > frame.range_max_m
    return Samples(v, u, np.where(bad, np.nan, z), too_close)


def usable(mount: Mounting) -> bool:
    """Whether a camera mounted so can give a virtual scan: its height must be known."""
    return mount.height_m > 0


@dataclass(frozen=True, slots=True)
class Plausible:
    """What a depth frame's intrinsics and its camera's mounting must satisfy to be trusted
    (the controller's settings): the frame's horizontal field of view within
    ``hfov_tolerance_deg`` of the announced one, fx/fy within 1/``max_pixel_aspect`` ..
    ``max_pixel_aspect``, the principal point inside the image, the camera lower than
    ``max_height_m`` (above it, nothing it sees could be an obstacle)."""

    hfov_tolerance_deg: float = 5.0
    max_pixel_aspect: float = 1.25
    max_height_m: float = 1.5


def frame_hfov_deg(intr: Intrinsics) -> float:
    """The horizontal field of view of a depth image by its intrinsics, in degrees."""
    return math.degrees(2.0 * math.atan(intr.width / (2.0 * intr.fx)))


def implausible(intr: Intrinsics, hfov_deg: float, mount: Mounting, p: Plausible) -> str:
    """Why a frame seen through ``intr`` by a camera announced with ``hfov_deg`` and mounted at
    ``mount`` cannot be trusted to show obstacles ("" when it can)."""
    values = (intr.fx, intr.fy, intr.cx, intr.cy)
    if not all(math.isfinite(x) for x in values) or intr.fx <= 0 or intr.fy <= 0:
        return f"intrinsics fx {intr.fx:g}, fy {intr.fy:g}, cx {intr.cx:g}, cy {intr.cy:g}"
    aspect = intr.fx / intr.fy
    if not 1.0 / p.max_pixel_aspect <= aspect <= p.max_pixel_aspect:
        return f"fx/fy {aspect:.3g} is not within 1/{p.max_pixel_aspect:g}..{p.max_pixel_aspect:g}"
    if not (0 <= intr.cx <= intr.width and 0 <= intr.cy <= intr.height):
        return (
            f"principal point ({intr.cx:g}, {intr.cy:g}) outside the "
            f"{intr.width}x{intr.height} image"
        )
    hfov = frame_hfov_deg(intr)
    if abs(hfov - hfov_deg) > p.hfov_tolerance_deg:
        return (
            f"the image's field of view {hfov:.1f} deg is not the announced {hfov_deg:g} deg "
            f"(within {p.hfov_tolerance_deg:g})"
        )
    if not mount.height_m < p.max_height_m:
        return (
            f"announced {mount.height_m:g} m above the floor, not below depth_max_height_m "
            f"({p.max_height_m:g})"
        )
    return ""


def blind_zone(intr: Intrinsics, mount: Mounting, distance_m: float) -> tuple[float, float]:
    """What a level camera cannot see below it: the distance (from the camera, along its axis)
    from which it sees the floor, and the height below which an obstacle ``distance_m`` ahead
    of it is unseen (0: none)."""
    down = (intr.height - intr.cy) / intr.fy  # tan of the lower half of the vertical view
    if down <= 0:
        return math.inf, mount.height_m
    return mount.height_m / down, max(0.0, mount.height_m - distance_m * down)


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
    seen through ``intr``: :func:`scan_samples` of its samples."""
    h, w = depth.shape
    if (w, h) != (intr.width, intr.height):
        raise ValueError(f"a {w}x{h} depth image with intrinsics for {intr.width}x{intr.height}")
    samples = sample_metres(depth, params.stride_px)
    return scan_samples(samples, intr, mount, params, header, range_max_m, range_min_m)


def scan_samples(
    samples: Samples,
    intr: Intrinsics,
    mount: Mounting,
    params: ScanParams,
    header: Header,
    range_max_m: float = 0.0,
    range_min_m: float = 0.0,
) -> LaserScan:
    """The virtual scan of a depth image's ``samples``: :func:`observe`'s ``scan``."""
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
    (services/controller/local_map.py) remembers them."""

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

    def ground(col: npt.NDArray[np.intp], zc: npt.NDArray[np.float64]) -> tuple[
        npt.NDArray[np.float64], npt.NDArray[np.float64]
    ]:
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
    band = _edge_band(~has_floor & (end == RUN_SOLID), rng[np.minimum(at, len(v) - 1), cols],
                      math.ceil(params.edge_band_px / params.stride_px))  # fmt: skip
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
        after = np.flatnonzero(kind[below][at[c]:, c] == FLOOR)
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


def merge(scans: Sequence[LaserScan]) -> LaserScan:
    """Several cameras' virtual scans (made with one resolution) as one: each ray the nearest
    range any of them reads (0, unknown, where one knows nothing there), NaN where none
    looks. The header is the oldest scan's (its age is the merged scan's)."""
    if not scans:
        raise ValueError("nothing to merge")
    first = scans[0]
    for scan in scans[1:]:
        if len(scan.ranges) != len(first.ranges) or scan.angle_min != first.angle_min:
            raise ValueError("virtual scans of different resolutions")
    ranges: npt.NDArray[np.float32] = np.fmin.reduce([s.ranges for s in scans]).astype(np.float32)
    oldest = min(scans, key=lambda s: s.header.stamp_ns)
    return LaserScan(
        header=oldest.header,
        angle_min=first.angle_min,
        angle_increment=first.angle_increment,
        range_min=0.0,
        range_max=max(s.range_max for s in scans),
        ranges=ranges,
    )


def looks_ahead(mount: Mounting, hfov_deg: float, sector_width_deg: float) -> bool:
    """Whether a camera's horizontal field of view overlaps the sector straight ahead."""
    off = abs(math.degrees(wrap(math.radians(mount.yaw_deg))))
    return off - hfov_deg / 2 < sector_width_deg / 2


def cover_sector(views: Sequence[tuple[float, float]], sector_width_deg: float) -> bool:
    """Whether the horizontal fields of view ``views`` ((yaw_deg, hfov_deg) each) together
    cover the whole sector of ``sector_width_deg`` straight ahead."""
    half = sector_width_deg / 2
    spans = []
    for yaw, hfov in views:
        if hfov >= 360:
            return True
        centre = math.degrees(wrap(math.radians(yaw)))
        for turn in (-360.0, 0.0, 360.0):  # a view across the rear reaches both ends
            spans.append((centre + turn - hfov / 2, centre + turn + hfov / 2))
    reached = -half
    for lo, hi in sorted(spans):
        if lo > reached:
            break
        reached = max(reached, hi)
    return reached >= half


@dataclass(frozen=True, slots=True)
class DepthCamera:
    """One announced depth camera at the control instant: where it stands, its field of view,
    its newest virtual scan (None: none yet) and that scan's age in seconds."""

    mount: Mounting
    hfov_deg: float
    scan: LaserScan | None = None
    age_s: float = math.inf


@dataclass(frozen=True, slots=True)
class DepthObstacles:
    """What the depth cameras show of the obstacles now: ``scan`` merged from every fresh
    camera's, its age (the oldest merged), or ``None`` with the reason in ``missing``."""

    scan: LaserScan | None
    age_s: float = math.inf
    missing: str = ""
    #: What the map remembers round the robot (services/controller/local_map.py): its
    #: hazard and unknown cells as a scan (None: no map), and how far ahead the corridor's
    #: floor is known.
    remembered: LaserScan | None = None
    known_m: float = math.inf


def depth_obstacles(
    cameras: Mapping[str, DepthCamera], timeout_s: float, sector_width_deg: float
) -> DepthObstacles:
    """The depth cameras' obstacles, or why there are none to drive forward on.

    Every camera that can give a virtual scan and looks into the sector ahead must have one
    no older than ``timeout_s``: one of them gone stale leaves part of the way ahead unseen,
    and forward motion stops as it does on a stale laser scan. Together their fields of view
    must cover the whole sector: what no camera sees is not known clear. Fresh scans of the other
    cameras (beside, behind) are merged too: the corridor the body sweeps reaches beyond the
    sector.
    """
    ahead = {
        c: cam
        for c, cam in cameras.items()
        if usable(cam.mount) and looks_ahead(cam.mount, cam.hfov_deg, sector_width_deg)
    }
    if not ahead:
        unknown = sorted(c for c, cam in cameras.items() if not usable(cam.mount))
        why = "no depth camera looks ahead"
        if unknown:
            why += f" ({', '.join(unknown)}: height above the floor unknown)"
        return DepthObstacles(None, missing=why)
    for c, cam in ahead.items():
        if cam.scan is None:
            return DepthObstacles(None, missing=f"no depth from {c} yet")
        if cam.age_s > timeout_s:
            return DepthObstacles(None, missing=f"no recent depth from {c} ({cam.age_s:.2f} s)")
    if not cover_sector([(c.mount.yaw_deg, c.hfov_deg) for c in ahead.values()], sector_width_deg):
        return DepthObstacles(
            None,
            missing=f"depth does not see the whole way ahead ({sector_width_deg:g} deg): "
            + ", ".join(sorted(ahead)),
        )
    fresh = [
        cam
        for cam in cameras.values()
        if usable(cam.mount) and cam.scan is not None and cam.age_s <= timeout_s
    ]
    scans = [cam.scan for cam in fresh if cam.scan is not None]
    return DepthObstacles(merge(scans), max(cam.age_s for cam in fresh))
