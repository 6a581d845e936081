"""A depth camera's image, as its library gives it, turned into a DepthFrame. Pure numpy.

Every depth source (a RealSense, an OAK, a folder of 16-bit PNGs) hands the service a
:class:`DepthImage`: the depth aligned to the colour frame read with it, in the library's own
units (a uint16 image in units of ``scale_m`` metres, or float32 metres), with the pinhole
intrinsics of that image. :func:`to_depth_frame` makes the message: 16UC1 in millimetres, the
colour frame's header, the sensor's range. A reading that millimetres cannot hold (beyond
65.535 m, NaN, negative) becomes 0, no reading: never a made-up number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from common.errors import ImageError
from common.images import Image
from common.messages import DepthFrame, Header

#: The largest reading 16UC1 millimetres can hold.
MAX_MM = 65535

Raw = npt.NDArray[np.uint16] | npt.NDArray[np.float32]


@dataclass(frozen=True, slots=True)
class DepthImage:
    """Depth aligned to a colour frame: ``data`` (h, w), uint16 in units of ``scale_m`` metres
    (0 = no reading) or float32 metres (``scale_m`` unused); ``fx``, ``fy``, ``cx``, ``cy`` in
    pixels of this image (pixel centres at integer coordinates)."""

    data: Raw
    scale_m: float
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        return int(self.data.shape[0])


def intrinsics_from_matrix(matrix: npt.ArrayLike) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) of a 3x3 camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (an
    OAK's calibration gives one)."""
    k = np.asarray(matrix, dtype=np.float64)
    if k.shape != (3, 3):
        raise ValueError(f"a camera matrix is 3x3, got shape {k.shape}")
    return float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2])


def intrinsics_for(
    intrinsics: tuple[float, float, float, float], hfov_deg: float, width: int, height: int
) -> tuple[float, float, float, float]:
    """The stated ``intrinsics`` (fx, fy, cx, cy), or, when all are 0, square pixels from the
    horizontal field of view with the principal point at the image's centre."""
    if any(intrinsics):
        return intrinsics
    # As perception.depth.Intrinsics.from_hfov, which the simulator and detector use.
    f = (width / 2) / math.tan(math.radians(hfov_deg) / 2)
    return f, f, width / 2, height / 2


def device_depth(
    colour: Image,
    depth: npt.NDArray[np.generic],
    *,
    scale_m: float,
    intrinsics: tuple[float, float, float, float],
) -> DepthImage:
    """A device's depth frame (already aligned to ``colour`` by its library) as a DepthImage
    with the colour stream's ``intrinsics``; ImageError when it is not an aligned depth image
    (not (h, w) uint16 or float32, or not the colour frame's size)."""
    if depth.ndim != 2 or depth.dtype not in (np.uint16, np.float32):
        raise ImageError(f"depth must be (h, w) uint16 or float32, got {depth.dtype} {depth.shape}")
    if depth.shape != colour.shape[:2]:
        raise ImageError(
            f"depth {depth.shape[1]}x{depth.shape[0]} is not aligned to the colour frame "
            f"{colour.shape[1]}x{colour.shape[0]}"
        )
    fx, fy, cx, cy = intrinsics
    return DepthImage(data=cast(Raw, depth), scale_m=scale_m, fx=fx, fy=fy, cx=cx, cy=cy)


def check_depth_png(data: npt.NDArray[np.generic], colour_size: tuple[int, int]) -> Raw:
    """A decoded depth PNG as a (h, w) uint16 image; ImageError saying why it cannot be one: not
    16-bit single-channel, or not the colour image's ``colour_size`` (width, height), which
    aligned depth has."""
    if data.dtype != np.uint16 or data.ndim != 2:
        channels = 1 if data.ndim == 2 else data.shape[2]
        raise ImageError(
            f"depth must be a 16-bit single-channel PNG, got {data.dtype} with {channels} "
            "channel(s)"
        )
    size = (int(data.shape[1]), int(data.shape[0]))
    if size != colour_size:
        raise ImageError(
            f"depth is {size[0]}x{size[1]}, its colour image {colour_size[0]}x{colour_size[1]} "
            "(aligned depth has the colour image's size)"
        )
    return cast(Raw, data)


def resized(image: DepthImage, size: tuple[int, int]) -> DepthImage:
    """``image`` at ``size`` (width, height), the colour frame's published size: nearest
    neighbour (a depth between an edge's two sides would be a made-up surface), the intrinsics
    scaled with it. (0, 0) or the same size: as it is."""
    width, height = size
    if size == (0, 0) or (image.width, image.height) == size:
        return image
    sx, sy = width / image.width, height / image.height
    data = cast(Raw, cv2.resize(image.data, (width, height), interpolation=cv2.INTER_NEAREST))
    return replace(
        image,
        data=data,
        fx=image.fx * sx,
        fy=image.fy * sy,
        cx=(image.cx + 0.5) * sx - 0.5,
        cy=(image.cy + 0.5) * sy - 0.5,
    )


def to_millimetres(image: DepthImage) -> npt.NDArray[np.uint16]:
    """The image in whole millimetres (0 = no reading); a uint16 image already in millimetres
    as it is."""
    if image.data.dtype == np.uint16 and image.scale_m == 0.001:
        return image.data.astype(np.uint16, copy=False)
    if image.data.dtype == np.uint16:
        mm = image.data.astype(np.float64) * (image.scale_m * 1000.0)
    else:
        mm = image.data.astype(np.float64) * 1000.0
    with np.errstate(invalid="ignore"):
        mm = np.rint(mm)
        valid = np.isfinite(mm) & (mm > 0) & (mm <= MAX_MM)
    return np.where(valid, mm, 0).astype(np.uint16)


def to_depth_frame(
    image: DepthImage, header: Header, *, range_min_m: float = 0.0, range_max_m: float = 0.0
) -> DepthFrame:
    """The DepthFrame of ``image`` (16UC1 millimetres) with the colour frame's ``header``;
    ValueError when the message cannot carry it (an absurd size or intrinsics)."""
    mm = to_millimetres(image)
    return DepthFrame(
        header=header,
        encoding="16UC1",
        width=image.width,
        height=image.height,
        data=np.ascontiguousarray(mm, dtype="<u2").tobytes(),
        fx=image.fx,
        fy=image.fy,
        cx=image.cx,
        cy=image.cy,
        range_min_m=range_min_m,
        range_max_m=range_max_m,
    )
