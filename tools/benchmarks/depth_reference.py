"""A reference of yolo_ros's depth method (mgonzs13/yolo_ros, ``convert_bb_to_3d`` in its 3D
node), written here from its description for the depth benchmark to measure ours against.

Per box: every valid pixel of the box (every 2nd row and column when the box holds 40,000
pixels or more), each weighted by its distance from the box's centre (a Gaussian of the
normalised radius with sigma 0.8, never under 0.3); a weighted histogram of depth over the
box's range (20 to 60 bins, about 1 cm each), smoothed by a 5-bin box filter; the mode is the
heaviest bin; the object is the depths within a threshold of the mode (3.5, 4 or 5 MADs by the
box's IQR, each clamped); with too few of them (under 15 %, or 6), the depths between the
weighted 2nd and 85th percentiles. The centre's z is the weighted mean of the object's depths
trimmed to the weighted 2..98 % and z's extent the weighted 1..99 %; the pixels within that z
range are back-projected and x and y each get a weighted median, a MAD gate and a weighted
trimmed (5..95 %) mean, their extents the weighted 3..97 %. No minimum pixel count: a box
with any valid pixel gets a position. Written as numpy for the comparison; not imported by the
stack.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from perception import DEPTH_COLUMNS as COLUMNS
from perception import Intrinsics
from perception import unknown_depth as unknown

F = npt.NDArray[np.float64]
Depth = npt.NDArray[np.float32]  # (h, w) metres, NaN where there is no reading


def measure_reference(
    depth: Depth, intr: Intrinsics, xyxy: npt.NDArray[np.float32]
) -> dict[str, npt.NDArray[np.float32]]:
    """The depth columns of boxes ``xyxy`` (n, 4) by the yolo_ros-like method."""
    out = unknown(len(xyxy))
    for i, box in enumerate(np.asarray(xyxy, np.float64).reshape(-1, 4)):
        row = _box(depth, intr, box)
        if row is not None:
            for name, value in zip(COLUMNS, row, strict=True):
                out[name][i] = value
    return out


def _box(depth: Depth, intr: Intrinsics, box: F) -> tuple[float, ...] | None:
    if not np.isfinite(box).all():
        return None
    x1, y1, x2, y2 = box
    # yolo_ros works from the box's integer centre and size
    cu, cv = int((x1 + x2) / 2), int((y1 + y2) / 2)
    su, sv = int(x2 - x1), int(y2 - y1)
    h, w = depth.shape
    u0, u1 = max(cu - su // 2, 0), min(cu + su // 2, w - 1)
    v0, v1 = max(cv - sv // 2, 0), min(cv + sv // 2, h - 1)
    if u1 <= u0 or v1 <= v0:
        return None
    step = 2 if su * sv >= 40000 else 1
    patch = depth[v0:v1:step, u0:u1:step]
    ok = np.isfinite(patch) & (patch > 0)
    if not ok.any():
        return None
    rows, cols = np.nonzero(ok)
    d = patch[rows, cols].astype(np.float64)
    us, vs = (u0 + cols * step).astype(np.float64), (v0 + rows * step).astype(np.float64)
    r = np.hypot((us - cu) / (su / 2 + 1e-6), (vs - cv) / (sv / 2 + 1e-6))
    wt = np.maximum(np.exp(-0.5 * (r / 0.8) ** 2), 0.3)
    zc, zmin, zmax = _depth_bounds(d, wt)
    if not np.isfinite(zc) or zc <= 0:
        return None
    keep = (d >= zmin) & (d <= zmax)
    if not keep.any():
        return None
    dk, wk = d[keep], wt[keep]
    xs = dk * (us[keep] - intr.cx) / intr.fx
    ys = dk * (vs[keep] - intr.cy) / intr.fy
    yc, ylo, yhi = _axis_bounds(ys, wk, 4.5, 0.06, 0.50)
    wide = float(np.std(dk)) > 0.15
    xc, xlo, xhi = _axis_bounds(xs, wk, *((4.0, 0.06, 0.40) if wide else (4.5, 0.08, 0.50)))
    dist = float(np.sqrt(xc * xc + yc * yc + zc * zc))
    return dist, xc, yc, zc, xhi - xlo, yhi - ylo, zmax - zmin


def _order(v: F, w: F) -> tuple[F, F, F]:
    """Values sorted, their weights, and the normalised cumulative weight."""
    o = np.argsort(v, kind="stable")
    cum = np.cumsum(w[o])
    if cum[-1] > 0:
        cum = cum / cum[-1]
    return v[o], w[o], cum


def _at(cum: F, f: float) -> int:
    return min(int(np.searchsorted(cum, f, side="left")), len(cum) - 1)


def _trimmed(
    v: F, w: F, trim: tuple[float, float], pct: tuple[float, float], mean_fallback: bool
) -> tuple[float, float, float]:
    sv, sw, cum = _order(v, w)
    lo, hi = _at(cum, trim[0]), _at(cum, trim[1])
    if hi > lo and sw[lo:hi].sum() > 0:
        centre = float((sv[lo:hi] * sw[lo:hi]).sum() / sw[lo:hi].sum())
    elif mean_fallback and w.sum() > 0:
        centre = float((v * w).sum() / w.sum())
    else:
        centre = float(np.median(v))
    return centre, float(sv[_at(cum, pct[0])]), float(sv[_at(cum, pct[1])])


def _depth_bounds(d: F, w: F) -> tuple[float, float, float]:
    if len(d) < 4:
        return float(np.median(d)), float(d.min()), float(d.max())
    dmin, dmax = float(d.min()), float(d.max())
    span = dmax - dmin
    if span <= 0:
        return float(np.median(d)), dmin, dmax
    bins = int(np.clip(round(span / 0.01), 20, 60))
    bw = span / bins
    idx = np.clip(((d - dmin) / bw).astype(np.int64), 0, bins - 1)
    hist = np.bincount(idx, w, bins)
    ks = min(5, bins // 4)
    half = ks // 2
    padded = np.concatenate((np.zeros(half), hist, np.zeros(half)))
    counts = np.convolve(np.ones(bins), np.ones(2 * half + 1), "same")
    smooth = np.convolve(padded, np.ones(2 * half + 1), "valid") / counts
    mode = dmin + bw * (int(np.argmax(smooth)) + 0.5)
    mad = float(np.median(np.abs(d - mode)))
    q25, q75 = np.percentile(d, [25, 75])
    iqr = q75 - q25
    if iqr < 0.03:
        thr = float(np.clip(3.5 * mad, 0.08, 0.30))
    elif iqr < 0.10:
        thr = float(np.clip(4.0 * mad, 0.12, 0.40))
    else:
        thr = float(np.clip(5.0 * mad, 0.15, 0.60))
    obj = np.abs(d - mode) <= thr
    if obj.sum() < max(6, int(len(d) * 0.15)):
        sv, _, cum = _order(d, w)
        p2, p85 = sv[_at(cum, 0.02)], sv[_at(cum, 0.85)]
        obj = (d >= p2) & (d <= p85)
    if not obj.any():
        obj = np.ones(len(d), bool)
    zc, zmin, zmax = _trimmed(d[obj], w[obj], (0.02, 0.98), (0.01, 0.99), True)
    if not zmin <= zc <= zmax:
        ext = max(zmax - zmin, 0.02)
        zmin, zmax = zc - ext / 2, zc + ext / 2
    if zmax - zmin < 0.02:
        zmin, zmax = zc - 0.01, zc + 0.01
    return zc, zmin, zmax


def _axis_bounds(
    v: F, w: F, mad_mult: float, clip_lo: float, clip_hi: float
) -> tuple[float, float, float]:
    if len(v) < 4:
        return float(np.median(v)), float(v.min()), float(v.max())
    sv, _, cum = _order(v, w)
    med = float(sv[_at(cum, 0.5)])
    dev = np.abs(v - med)
    thr = float(np.clip(mad_mult * float(np.median(dev)), clip_lo, clip_hi))
    keep = dev <= thr
    if keep.sum() < max(4.0, len(v) * 0.12):
        keep = np.ones(len(v), bool)
    c, lo, hi = _trimmed(v[keep], w[keep], (0.05, 0.95), (0.03, 0.97), False)
    if hi - lo < 0.02:
        lo, hi = c - 0.01, c + 0.01
    return c, lo, hi
