"""The faults of the harder world's cameras, beyond today's noise and holes. Pure.

Depth (used by simworld/depth.py's :func:`~simworld.depth.apply`, set by
:class:`~simworld.depth.DepthNoise`, whose docstring gives each figure's source):

- :func:`edge_faults`: at a depth edge between two surfaces, a share of the edge band reads a
  mix of the near and the far surface (flying pixels) instead of nothing.
- :func:`range_bias`: a systematic error growing with the square of the range.
- :func:`mirror_reads`: a mirror-like face (``Material.MIRROR``) reads what it reflects: farther
  than the face.

Colour (the simulator applies them to the image it publishes; the depth camera's own faults
are drawn from the clean image):

- :func:`motion_blur`: a horizontal smear while the robot turns, ``yaw rate x exposure x
  focal length`` pixels long.
- :class:`Exposure`: brightness that jumps when the camera turns towards or away from the
  light and comes back as auto-exposure catches up, plus a slow drift of the gain.

Every random draw comes from the generator the caller passes (the simulator seeds it from
``sim.seed``), so a run is reproducible; a fault that is off draws nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from common.images import Image
from simworld.render import CameraSpec, layout
from simworld.walls import in_front, wall_view
from simworld.world import Material, World

Depth = npt.NDArray[np.float32]  # (h, w) metres, NaN = no reading
Mask = npt.NDArray[np.bool_]


# -- depth ------------------------------------------------------------------------------------
def edge_kinds(truth: Depth, jump: float) -> tuple[Mask, Mask]:
    """The pixels on either side of a depth discontinuity, in two kinds: ``between`` two
    readings (neighbours, right or below, whose z differ by more than ``jump`` of the nearer)
    and ``beside_none`` (a reading next to no reading). Together they are
    :func:`simworld.depth.depth_edges`."""
    valid = np.isfinite(truth)
    z = np.where(valid, truth, 0.0)
    between = np.zeros(truth.shape, bool)
    beside_none = np.zeros(truth.shape, bool)
    for axis in (0, 1):
        a, va = np.swapaxes(z, 0, axis), np.swapaxes(valid, 0, axis)
        both = va[1:] & va[:-1]
        jumps = both & (np.abs(a[1:] - a[:-1]) > jump * np.minimum(a[1:], a[:-1]))
        one = va[1:] != va[:-1]
        for out, step in ((between, jumps), (beside_none, one)):
            e = np.swapaxes(out, 0, axis)
            e[1:] |= step
            e[:-1] |= step
    return between, beside_none


def _dilate(mask: Mask, px: int) -> Mask:
    size = 2 * px + 1
    return cv2.dilate(mask.view(np.uint8), np.ones((size, size), np.uint8)).view(bool)


def edge_faults(
    truth: Depth, edge_px: int, jump: float, share: float, rng: np.random.Generator
) -> tuple[Mask, Mask, Depth]:
    """What a depth camera reads within ``edge_px`` pixels of a depth edge: ``(hole, flying,
    values)``. Beside no reading (the wall at infinity, a dark face) the band reads nothing, as
    before. Between two readings each band pixel is, with probability ``share``, a flying
    pixel: it reads ``near + u * (far - near)``, u uniform in (0, 1), where near and far are
    the nearest and farthest readings within ``edge_px + 1`` pixels (both sides of the edge);
    else it reads nothing. ``values`` holds the flying pixels' readings (NaN elsewhere)."""
    between, beside_none = edge_kinds(truth, jump)
    hole = _dilate(beside_none, edge_px)
    band = _dilate(between, edge_px) & ~hole
    ys, xs = np.nonzero(band)
    fly = rng.random(ys.size) < share
    valid = np.isfinite(truth)
    size = 2 * (edge_px + 1) + 1
    kernel = np.ones((size, size), np.uint8)
    near = cv2.erode(np.where(valid, truth, np.inf).astype(np.float32), kernel)
    far = cv2.dilate(np.where(valid, truth, -np.inf).astype(np.float32), kernel)
    flying = np.zeros(truth.shape, bool)
    flying[ys[fly], xs[fly]] = True
    hole[ys[~fly], xs[~fly]] = True
    values = np.full(truth.shape, np.nan, np.float32)
    u = rng.random(int(fly.sum()))
    n, f = near[flying], far[flying]
    values[flying] = n + u * (f - n)
    return hole, flying, values


def range_bias(z: Depth, bias_k: float) -> Depth:
    """The systematic error of a reading ``z`` (metres): ``bias_k * z^2`` (positive: it reads
    farther), the first-order effect of a constant disparity offset in a stereo camera."""
    out: Depth = (bias_k * np.nan_to_num(z, nan=0.0) ** 2).astype(np.float32)
    return out


def mirror_reads(world: World, spec: CameraSpec, truth: Depth, scale: float) -> Depth:
    """``truth`` with every visible pixel of a ``Material.MIRROR`` obstacle reading ``scale``
    times its face's depth (what the mirror shows: the robot's side of the room, behind the
    camera, about as far again as the mirror is); ``truth`` itself when there is none or
    ``scale`` is 1. Nearer things drawn over the mirror keep their own reading."""
    if scale == 1.0 or not any(o.material == Material.MIRROR for o in world.obstacles):
        return truth
    mirror = np.zeros(truth.shape, bool)
    view = wall_view(world, spec)
    for p in layout(world, spec):  # drawing order: a nearer thing covers the mirror
        if p.rect is not None:
            x0, y0, x1, y1 = p.rect
            shown = in_front(view, p.rect, p.z - p.radius)  # a nearer wall covers it too
            if shown is None:
                mirror[y0:y1, x0:x1] = p.material == Material.MIRROR
            else:
                mirror[y0:y1, x0:x1][shown] = p.material == Material.MIRROR
    out = truth.copy()
    out[mirror] *= np.float32(scale)
    return out


# -- colour -----------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class ColourFaults:
    """A colour camera's faults (the ``sim.colour_*`` settings); zeros turn each off.

    ``exposure_s``: the exposure time; a turning robot smears the image horizontally by
    ``yaw rate x exposure_s x focal length`` pixels (:func:`motion_blur`).

    ``light_change``: the scene's brightness in the log, ``light_change * cos(heading -
    light bearing)``: facing the light (a window) it is ``e^light_change`` (+35 % at 0.3) of
    side-lit, facing away ``e^-light_change``. Auto-exposure follows it with the time constant
    ``light_tau_s``, so a turn shows as a brightness jump that fades (:class:`Exposure`).

    ``drift``/``drift_tau_s``: a slow random drift of the gain (its sigma in the log, and its
    time constant): auto-exposure hunting, lights and clouds.
    """

    exposure_s: float = 0.0
    light_change: float = 0.0
    light_tau_s: float = 1.0
    drift: float = 0.0
    drift_tau_s: float = 10.0

    @property
    def on(self) -> bool:
        return self.exposure_s > 0 or self.light_change > 0 or self.drift > 0


def blur_px(yaw_rate: float, exposure_s: float, focal_px: float) -> float:
    """How far (pixels) the image moves during one exposure while the camera turns at
    ``yaw_rate`` (rad/s): at the image's centre ``focal_px * yaw_rate * exposure_s``."""
    return abs(yaw_rate) * exposure_s * focal_px


def motion_blur(image: Image, yaw_rate: float, exposure_s: float, focal_px: float) -> Image:
    """``image`` smeared horizontally by :func:`blur_px` pixels (a box of that length, rounded;
    under 2 px the image itself)."""
    length = round(blur_px(yaw_rate, exposure_s, focal_px))
    if length < 2:
        return image
    return np.asarray(cv2.blur(image, (length, 1), borderType=cv2.BORDER_REPLICATE), np.uint8)


class Exposure:
    """One colour camera's brightness over time: its gain is ``exp(scene - adapted +
    drift)``, ``scene`` the log brightness of where it looks (:class:`ColourFaults`),
    ``adapted`` the auto-exposure's lagging estimate of it, ``drift`` a slow random walk
    pulled back to 0 (Ornstein-Uhlenbeck). It starts adapted, with no drift."""

    def __init__(self, faults: ColourFaults, light_bearing: float) -> None:
        self.faults = faults
        self.light_bearing = light_bearing
        self.adapted: float | None = None
        self.drift = 0.0
        self.t: float | None = None

    def scene(self, heading: float) -> float:
        return self.faults.light_change * math.cos(heading - self.light_bearing)

    def gain(self, t: float, heading: float, rng: np.random.Generator) -> float:
        """The gain at time ``t`` (s; a clock that goes back restarts the lag, not the state)
        for a camera looking along ``heading`` (rad, world frame)."""
        f, scene = self.faults, self.scene(heading)
        dt = 0.0 if self.t is None else max(0.0, t - self.t)
        self.t = t
        if self.adapted is None:
            self.adapted = scene
        else:
            self.adapted += (scene - self.adapted) * (1.0 - math.exp(-dt / f.light_tau_s))
        if f.drift > 0 and dt > 0:
            keep = math.exp(-dt / f.drift_tau_s)
            step = f.drift * math.sqrt(1.0 - keep * keep) * float(rng.standard_normal())
            self.drift = self.drift * keep + step
        return math.exp(scene - self.adapted + self.drift)


def colour_faults(
    image: Image,
    exposure: Exposure,
    t: float,
    heading: float,
    yaw_rate: float,
    focal_px: float,
    rng: np.random.Generator,
) -> Image:
    """``image`` as the colour camera delivers it at time ``t``: blurred by the turn, then
    scaled by the exposure's gain (saturating at 255). ``image`` is not changed."""
    f = exposure.faults
    out = motion_blur(image, yaw_rate, f.exposure_s, focal_px) if f.exposure_s > 0 else image
    if f.light_change > 0 or f.drift > 0:
        gain = exposure.gain(t, heading, rng)
        out = np.asarray(cv2.convertScaleAbs(out, alpha=gain), np.uint8)
    return out
