"""The depth image a camera on the simulated robot sees, aligned to its colour image. Pure.

:func:`render_depth` draws the truth from the same geometry as the colour image
(simworld/render.py :func:`~simworld.render.layout`), pixel for pixel: a reading is
the z (distance along the optical axis) of what the pixel sees, in metres, NaN where it sees
nothing.

- The floor, below the horizon: row ``v`` (its centre at ``v + 0.5``) sees the floor at
  ``z = f * camera_height / (v + 0.5 - cy)``.
- Above the horizon the wall is at infinity: no reading.
- Beyond a drop-off's edge the floor is lower: a floor pixel whose ray meets the upper floor
  inside a :class:`~simworld.world.Drop` reads ``z * (h + depth_m) / h``, where the same
  ray meets the lower floor (simworld/floor.py, which ignores the drop's walls).
- Every drawn thing reads its front face, ``z - radius``: a target (its whole drawn
  rectangle: the cut-out is a rectangle of photo) and an obstacle (a round thing drawn as a
  box) alike, unless its material reads nothing: a dark obstacle (no texture, no pattern
  returned) and a glass one read NaN over their whole face, whatever the noise settings
  (what is behind glass is not read either: a real stereo camera's reading there is
  unreliable, and a hole is the honest worst case). A face is the nearest point of the circle
  the laser sees (simworld/laser.py), and what a real depth camera sees of a person: their
  front, not their middle. The colour image still draws a target at its centre's z (its size
  in the image).
- Things are drawn in the colour image's order (farthest centre first, nearer over farther),
  so the depth covers exactly the pixels the colour image does, whatever is in front.

:class:`DepthNoise` and :func:`apply` give the truth a stereo depth camera's faults; see each
field. :func:`targets_in_camera` gives the point of each visible target's front face a depth
camera sees (in the optical frame), the truth a depth method is measured against;
:func:`depth_frame` makes the message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np
import numpy.typing as npt

from common.images import Image
from common.messages import DepthFrame, Header
from simworld.faults import edge_faults, range_bias
from simworld.floor import drop_scale
from simworld.people import drawn_area, stamp
from simworld.render import CameraSpec, Placed, layout
from simworld.walls import in_front, wall_view
from simworld.world import Material, World

Depth = npt.NDArray[np.float32]  # (h, w) metres, NaN = no reading

#: The largest reading a 16UC1 image holds (mm).
MAX_MM = 65535


@cache
def floor_depth(spec: CameraSpec) -> Depth:
    """The empty world's depth: the floor below the horizon, NaN above it (read-only)."""
    f, cy = spec.focal_px, spec.height / 2
    below = np.arange(spec.height, dtype=np.float64) + 0.5 - cy  # pixels under the horizon
    with np.errstate(divide="ignore"):
        z = np.where(below > 0, f * spec.height_m / np.where(below > 0, below, 1.0), np.nan)
    out = np.repeat(z.astype(np.float32)[:, None], spec.width, axis=1)
    out.setflags(write=False)
    return out


#: Materials whose face a depth camera reads nothing on (world.Material says why).
UNREAD = frozenset({Material.DARK, Material.GLASS})


def placed_depth(p: Placed) -> float:
    """The z one drawn thing reads on the ray through its centre at half its height: a flat
    thing's front face, ``z - radius``, target or obstacle; a person with a body, their
    front surface there (the body's ``truth_dz`` from its axis); NaN for a material a depth
    camera reads nothing on (:data:`UNREAD`)."""
    if p.material in UNREAD:
        return math.nan
    return p.z - p.radius if p.body is None else p.z + p.body.truth_dz


def render_depth(world: World, spec: CameraSpec) -> Depth:
    """The true depth image (``spec.height``, ``spec.width``) float32 metres of ``world`` from
    the camera ``spec``, aligned pixel for pixel with ``render(world, spec)``; NaN: no reading
    (the wall at infinity, a dark or glass face). A person with a body reads their front
    surface over their silhouette, and what is behind them around it and between their legs.
    A wall (simworld/walls.py) reads its depth per pixel (a dark one nothing), and hides what
    is farther; a glass wall reads nothing where it is nearer than what is behind it."""
    scale = drop_scale(world, spec)
    out = floor_depth(spec).copy() if scale is None else floor_depth(spec) * scale
    view = wall_view(world, spec)
    scene_z = None
    if view is not None:
        scene_z = np.minimum(np.nan_to_num(out, nan=np.inf), view.z)
        out[view.opaque] = view.z[view.opaque]
        out[view.dark(world)] = np.nan
    for p in layout(world, spec):
        if p.rect is None:
            continue
        x0, y0, x1, y1 = p.rect
        st = None if p.body is None else stamp(p.body, p.full, p.rect)
        z: float | Depth = p.z - p.radius if st is None else np.float32(p.z) + st.dz
        on = in_front(view, p.rect, z)
        if st is not None:
            on = st.alpha > 0 if on is None else on & (st.alpha > 0)
        value = np.float32(placed_depth(p)) if st is None else z
        reading = np.broadcast_to(value, (y1 - y0, x1 - x0))
        if on is None:
            out[y0:y1, x0:x1] = reading
            continue
        out[y0:y1, x0:x1][on] = reading[on]
        if scene_z is not None:
            scene_z[y0:y1, x0:x1][on] = np.broadcast_to(np.float32(z), reading.shape)[on]
    if view is not None and scene_z is not None and view.glass:
        out[view.glass_z < scene_z] = np.nan
    return out


def owners(world: World, spec: CameraSpec) -> tuple[npt.NDArray[np.int32], list[Placed]]:
    """Which drawn thing each pixel shows (its index in the list, -1: none: the floor, a
    wall), and the drawn things (:func:`~simworld.render.layout`), as the colour image draws
    them: a flat thing over its whole rectangle, a person with a body over their silhouette,
    each only where it is nearer than an opaque wall (a glass one hides nothing)."""
    placed = layout(world, spec)
    view = wall_view(world, spec)
    owner = np.full((spec.height, spec.width), -1, np.int32)
    for k, p in enumerate(placed):
        if p.rect is None:
            continue
        x0, y0, x1, y1 = p.rect
        st = None if p.body is None else stamp(p.body, p.full, p.rect)
        on = in_front(view, p.rect, p.z - p.radius if st is None else np.float32(p.z) + st.dz)
        if st is not None:
            on = st.alpha > 0 if on is None else on & (st.alpha > 0)
        if on is None:
            owner[y0:y1, x0:x1] = k
        else:
            owner[y0:y1, x0:x1][on] = k
    return owner, placed


def placed_area(p: Placed) -> float:
    """How many pixels ``p`` covers whole, in the image or out of it."""
    if p.body is not None:
        return drawn_area(p.body, p.full)
    x0, y0, x1, y1 = p.full
    return float((x1 - x0) * (y1 - y0))


def targets_in_camera(
    world: World, spec: CameraSpec, min_visible: float = 0.0
) -> list[tuple[str, str, float, float, float]]:
    """Each target the camera sees, as (target id, name, x, y, z): the point of its surface
    that a depth camera sees on the ray through its centre at half its height, in the camera's
    optical frame (metres: x right, y down, z forward). That is the target's centre at half
    its height (x, y, z) back-projected at the depth :func:`placed_depth` reads there:
    (x, y, z) scaled by ``depth / z``. A flat target's is its front face, ``z - radius``; a
    person with a body's, the front of their torso on their axis at half their height (the
    hips; about the centre's less half the body's thickness front-on, less half its width
    side-on), what a depth method reading the middle of the person's box should find. The
    hidden middle of the target is no camera's truth.

    A target is seen when more than ``min_visible`` of it (its whole drawn rectangle, or a
    body's whole silhouette; cut by the image's edges or hidden by nearer things counts as not
    seen) shows in the image."""
    owner, placed = owners(world, spec)
    shown = np.bincount(owner[owner >= 0].ravel(), minlength=len(placed))
    out = []
    for k, p in enumerate(placed):
        if p.target is None or p.rect is None:
            continue
        if shown[k] <= min_visible * placed_area(p):
            continue
        tg = world.targets[p.target]
        face = placed_depth(p)
        if face <= 0:
            continue  # the camera is inside it: no surface in front to see
        x, y = 0.0 - p.lateral, spec.height_m - p.height_m / 2
        scale = face / p.z
        out.append((tg.id, tg.name, float(x * scale), float(y * scale), float(face)))
    return out


@dataclass(frozen=True, slots=True)
class DepthNoise:
    """A stereo depth camera's faults (the ``sim.depth_*`` settings); zeros turn each off.
    ``DepthNoise()`` is today's camera (the "simple" world's): the newer faults (``bias_k``,
    ``flying_share``, ``mirror_scale``, ``in_disparity``) default off here; the harder
    world's figures are the ``sim.depth_*`` settings' defaults (services/sim/contract.py).
    The camera named is Intel's RealSense D435 (active IR stereo, baseline b = 50 mm, about
    90 deg hfov), whose datasheet (Intel RealSense D400 Series Product Family Datasheet,
    "Depth Quality Specification"; at 2 m, 848x480, 80 % of the field) allows an RMS error
    (spatial noise) and an absolute error (Z-accuracy) of up to 2 % each, a temporal noise of
    up to 1 %.

    ``range_min_m``/``range_max_m``: readings outside are no readings (0 in the 16UC1 image).
    The D4 matcher searches a fixed number of disparities, so its minimum range (the
    datasheet's Min-Z) scales with the resolution: about 0.28 m at 1280x720, less at lower
    ones; 0.3 m is the conservative figure a robot should assume. Beyond ~10 m its depth is
    noise.

    ``noise_k``: the reading's noise, sigma = ``noise_k`` * z^2 (metres). A stereo camera
    measures disparity d = f * b / z with a roughly constant sub-pixel error e, so its depth
    error is z^2 * e / (f * b) (Grunnet-Jepsen et al., "Tuning depth cameras for best
    performance", Intel white paper: RMS error = z^2 x subpixel / (f x b), subpixel typically
    0.08 px). The D435 at the 640x480 the simulator streams: f = 320 px (90 deg), b = 50 mm,
    e = 0.08 px: 0.005 per metre, 1 % at 2 m (2 cm), 2.5 % at 5 m, 5 % at 10 m; within the
    datasheet's 2 % RMS at 2 m (``noise_k`` 0.01 is that bound), at its 1 % temporal noise.

    ``noise_corr_px``: the noise's correlation length in pixels, 0 = independent pixels. A
    stereo matcher finds each pixel's disparity by comparing a window of pixels round it (a
    D4-class camera: about 7x7 to 9x9 at 640x480), and the camera's own spatial filter
    smooths further, so neighbours share most of their error: a real depth image's noise is
    blobs several pixels wide, not salt and pepper, and a median over a box averages far
    fewer independent errors than it has pixels. The noise is white noise blurred by a
    Gaussian of this sigma, rescaled so that each pixel's sigma is still ``noise_k`` * z^2;
    pixels d apart then correlate exp(-d^2 / (4 sigma^2)). 4 px: a neighbour 0.98, half at
    6.7 px (about the matcher's window), 0.37 at 8 px.

    ``bias_k``: a systematic error, ``bias_k`` * z^2 metres added to every reading (positive:
    it reads farther; noise has zero mean, this does not, and no average removes it). A
    stereo camera whose calibration is off by a constant disparity offset delta reads f b /
    (f b / z + delta), about z - delta z^2 / (f b): a bias growing with the square of the
    range, as its noise does. The datasheet bounds it at 2 % at 2 m (``bias_k`` 0.01); one
    D435 measured out of the box read 980.7 mm at 1 m (M. Calvert, "Improving the depth map
    accuracy of RealSense cameras", 2018). The harder world's 0.0025 (0.5 % at 2 m, 1.25 %
    at 5 m, 2.5 % at 10 m; delta = 0.04 px at 640x480) is a well-calibrated unit at a quarter
    of the bound.

    ``edge_px``: pixels within this many pixels of a depth discontinuity (neighbours whose z
    differ by more than ``edge_jump`` of the nearer, or a reading next to none) read nothing,
    as stereo matching fails where one eye sees what the other does not. ``flying_share``:
    of those between two readings (not beside a pixel of no reading), this share read a value
    between the near and the far surface instead (simworld/faults.py
    :func:`~simworld.faults.edge_faults`): flying pixels, as a matching window that straddles
    the edge finds a disparity between the two surfaces' (the "foreground fattening" and
    mixed matches of window-based stereo, Scharstein & Szeliski, IJCV 47, 2002; a
    time-of-flight camera's mixed pixels do the same). 0: today's holes alone; 1: no holes
    between two surfaces, only flying pixels. The harder world's 0.5 is a choice, not a
    datasheet figure: the D4's left-right check removes some edge pixels, not all.

    ``mirror_scale``: a ``Material.MIRROR`` face (simworld/world.py) reads this many times its
    depth (:func:`~simworld.faults.mirror_reads`): the projector's dots and the texture seen
    there are the reflection's, so the matcher finds what the mirror shows, farther than the
    face. 1: it reads its face as a solid one does. The harder world's 2: a mirror facing the
    camera shows the camera's side of the room at about twice its own distance.

    ``in_disparity``: the noise and the bias are added to the inverse depth (the disparity
    over f b, what a stereo camera measures: ``1 / (1 / z - bias_k + noise_k * n)``), not
    to the range (``z + bias_k z^2 + noise_k z^2 n``). The two agree to first order where the
    error is small; far away they do not: in range space a floor pixel just under the horizon
    (truth 60 m, sigma 18 m) can read 0.5 m, a phantom obstacle at the camera's feet, where a
    real camera's disparity error (sigma 0.005 m^-1 here) leaves it far or no reading at all
    (a disparity at or below zero). The harder world's true; false: today's.

    ``dark_level``/``dark_dropout``: colour pixels whose grey level is below ``dark_level``
    (0..255) read nothing with probability ``dark_dropout`` (little texture, little reflected
    pattern). ``dropout``: any pixel reads nothing with this probability.

    Readings are quantised to millimetres, as a 16UC1 image carries them.
    """

    range_min_m: float = 0.3
    range_max_m: float = 10.0
    noise_k: float = 0.005
    noise_corr_px: float = 4.0
    edge_px: int = 2
    edge_jump: float = 0.1
    dark_level: int = 30
    dark_dropout: float = 0.5
    dropout: float = 0.01
    bias_k: float = 0.0
    flying_share: float = 0.0
    mirror_scale: float = 1.0
    in_disparity: bool = False


#: A perfect depth camera (still range-limited and quantised to mm).
IDEAL = DepthNoise(noise_k=0.0, edge_px=0, dark_dropout=0.0, dropout=0.0)


def depth_edges(truth: Depth, jump: float) -> npt.NDArray[np.bool_]:
    """Pixels on either side of a depth discontinuity: a neighbour (right or below) whose z
    differs by more than ``jump`` of the nearer of the two, or a reading next to none."""
    valid = np.isfinite(truth)
    z = np.where(valid, truth, 0.0)
    edge = np.zeros(truth.shape, bool)
    for axis in (0, 1):
        a = np.swapaxes(z, 0, axis)
        va = np.swapaxes(valid, 0, axis)
        near = np.minimum(a[1:], a[:-1])
        step = (va[1:] != va[:-1]) | (va[1:] & va[:-1] & (np.abs(a[1:] - a[:-1]) > jump * near))
        e = np.swapaxes(edge, 0, axis)
        e[1:] |= step
        e[:-1] |= step
    return edge


@cache
def _blur_kernel(corr_px: float) -> tuple[int, float]:
    """The blur's kernel size (odd, 3 sigmas each side) for ``corr_px``, and the factor that
    brings the blurred unit white noise back to a sigma of 1: 1 / sqrt(sum of the 2D kernel's
    squared weights), the kernel being separable: 1 / sum of the 1D kernel's squares."""
    ksize = 2 * math.ceil(3 * corr_px) + 1
    g = cv2.getGaussianKernel(ksize, corr_px, cv2.CV_64F)
    return ksize, float(1.0 / np.sum(g**2))


def unit_noise(shape: tuple[int, ...], corr_px: float, rng: np.random.Generator) -> Depth:
    """Gaussian noise of sigma 1 per pixel (float32, ``shape``), correlated over ``corr_px``
    pixels (the sigma of the blur of white noise; 0: independent pixels). The white noise is
    drawn a kernel's half-width larger on every side and cropped, so pixels at the image's
    edge have the same sigma and correlation as the rest."""
    if corr_px <= 0:
        return rng.standard_normal(shape, dtype=np.float32)
    ksize, scale = _blur_kernel(corr_px)
    r = ksize // 2
    h, w = shape
    white = rng.standard_normal((h + 2 * r, w + 2 * r), dtype=np.float32)
    blurred = cv2.GaussianBlur(white, (ksize, ksize), corr_px, borderType=cv2.BORDER_CONSTANT)
    out: Depth = np.asarray(blurred[r : r + h, r : r + w], np.float32) * np.float32(scale)
    return out


def _in_disparity(z: Depth, noise: DepthNoise, rng: np.random.Generator) -> Depth:
    """``z`` with its noise and bias added where a stereo camera makes them, to the inverse
    depth (disparity over f b): ``1 / (1 / z - bias_k + noise_k * n)``, n correlated unit
    noise; to first order the range-space ``z + bias_k z^2 + noise_k z^2 n``. Where the
    inverse depth comes out at or below zero (a far pixel, its disparity lost in the noise)
    there is no reading. A far reading's error is then lopsided and unbounded only towards
    far, as a real one's: near the horizon (truth 60 m, range-space sigma 18 m) a pixel can
    read 0.5 m in range space, never here (that would be a disparity error of ~380 sigma)."""
    with np.errstate(divide="ignore"):
        inv = np.float32(1.0) / z  # NaN stays NaN
    if noise.bias_k != 0:
        inv -= np.float32(noise.bias_k)
    if noise.noise_k > 0:
        inv += unit_noise(z.shape, noise.noise_corr_px, rng) * np.float32(noise.noise_k)
    with np.errstate(divide="ignore", invalid="ignore"):
        out: Depth = np.where(inv > 0, np.float32(1.0) / inv, np.float32(np.nan)).astype(np.float32)
    return out


def apply(truth: Depth, colour_bgr: Image, noise: DepthNoise, rng: np.random.Generator) -> Depth:
    """``truth`` as the depth camera reads it: flying pixels, noise, bias, holes at edges, on
    dark surfaces and at random, millimetre quantisation, and the range limits. float32
    metres, NaN = no reading; ``colour_bgr`` is the aligned colour image (same size). A fault
    that is off draws nothing from ``rng``: with the newer faults off, today's output bit for
    bit."""
    z = truth.astype(np.float32, copy=True)
    edge_hole = None
    if noise.edge_px > 0 and noise.flying_share > 0:
        edge_hole, flying, values = edge_faults(
            truth, noise.edge_px, noise.edge_jump, noise.flying_share, rng
        )
        z[flying] = values[flying]
    if noise.in_disparity:
        z = _in_disparity(z, noise, rng)
    else:
        shift = range_bias(z, noise.bias_k) if noise.bias_k != 0 else None
        if noise.noise_k > 0:
            sigma = noise.noise_k * np.nan_to_num(z, nan=0.0) ** 2
            z += (unit_noise(z.shape, noise.noise_corr_px, rng) * sigma).astype(np.float32)
        if shift is not None:
            z += shift
    z *= 1000.0
    np.round(z, out=z)
    z /= 1000.0
    hole = ~((z >= noise.range_min_m) & (z <= min(noise.range_max_m, MAX_MM / 1000.0)))
    if edge_hole is not None:
        hole |= edge_hole
    elif noise.edge_px > 0:
        edges = depth_edges(truth, noise.edge_jump).astype(np.uint8)
        size = 2 * noise.edge_px + 1
        hole |= cv2.dilate(edges, np.ones((size, size), np.uint8)).astype(bool)
    if noise.dark_dropout > 0 and noise.dark_level > 0:
        grey = cv2.cvtColor(colour_bgr, cv2.COLOR_BGR2GRAY)
        dark = grey < noise.dark_level
        hole |= dark & (rng.random(z.shape, dtype=np.float32) < noise.dark_dropout)
    if noise.dropout > 0:
        hole |= rng.random(z.shape, dtype=np.float32) < noise.dropout
    z[hole] = np.nan
    return z


def depth_frame(depth_m: Depth, spec: CameraSpec, header: Header, noise: DepthNoise) -> DepthFrame:
    """``depth_m`` (metres, NaN = no reading) as a 16UC1 DepthFrame in millimetres (0 = no
    reading), with ``spec``'s intrinsics (square pixels, the principal point at the centre)
    and ``noise``'s range."""
    mm = np.nan_to_num(np.round(depth_m * 1000.0), nan=0.0, posinf=0.0, neginf=0.0)
    data = np.clip(mm, 0, MAX_MM).astype("<u2").tobytes()
    return DepthFrame(
        header=header,
        encoding="16UC1",
        width=spec.width,
        height=spec.height,
        data=data,
        fx=spec.focal_px,
        fy=spec.focal_px,
        cx=spec.width / 2,
        cy=spec.height / 2,
        range_min_m=noise.range_min_m,
        range_max_m=noise.range_max_m,
    )
