"""A cheap appearance cue for each detection: the colour histogram of the middle of its box,
what a tracker compares to tell one person from another after an occlusion. Pure.

The histogram is taken over the box's middle (:data:`CROP`: a person's torso and thighs,
their clothes, not the background round them) in HSV, :data:`BINS` bins a channel, and
normalised to sum 1; :func:`similarity` is the Bhattacharyya coefficient of two, 1 for the
same colours, 0 for none in common. Hue alone would fail on black, white and grey clothes
(their hue is noise): the value and saturation bins tell those apart.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from common.images import Image

#: The part of a box the histogram is taken over: (left, top, right, bottom) as shares of its
#: width and height.
CROP = (0.25, 0.2, 0.75, 0.65)
#: Bins per channel (hue, saturation, value).
BINS = (8, 3, 3)
FEATURES = BINS[0] * BINS[1] * BINS[2]

Features = npt.NDArray[np.float32]  # (n, FEATURES), each row sums to 1 (0 for an empty crop)


def appearance(image: Image, xyxy: npt.NDArray[np.floating]) -> Features:
    """The colour histogram of each box of ``xyxy`` (n, 4, pixels of ``image``, BGR)."""
    h, w = image.shape[:2]
    out = np.zeros((len(xyxy), FEATURES), np.float32)
    for k, (x0, y0, x1, y1) in enumerate(np.asarray(xyxy, np.float64)):
        bw, bh = x1 - x0, y1 - y0
        cx0 = int(np.clip(x0 + CROP[0] * bw, 0, w))
        cx1 = int(np.clip(x0 + CROP[2] * bw, 0, w))
        cy0 = int(np.clip(y0 + CROP[1] * bh, 0, h))
        cy1 = int(np.clip(y0 + CROP[3] * bh, 0, h))
        if cx1 <= cx0 or cy1 <= cy0:
            continue
        # Every other pixel each way: a quarter of the work, the same colours in proportion.
        crop = image[cy0:cy1:2, cx0:cx1:2]
        hsv = cv2.cvtColor(np.ascontiguousarray(crop), cv2.COLOR_BGR2HSV)
        hist = cv2.calcHist([hsv], [0, 1, 2], None, list(BINS), [0, 180, 0, 256, 0, 256])
        total = float(hist.sum())
        if total > 0:
            out[k] = hist.ravel() / total
    return out


def similarity(a: Features, b: Features) -> npt.NDArray[np.float64]:
    """The Bhattacharyya coefficient of every row of ``a`` (n, k) with every row of ``b``
    (m, k): (n, m), 0..1."""
    out: npt.NDArray[np.float64] = (
        np.sqrt(np.asarray(a, np.float64)) @ np.sqrt(np.asarray(b, np.float64)).T
    )
    return out
