"""Depth frames for the detector's depth tests (unit and integration): a flat scene at a
known distance, with holes where asked, aligned to a colour frame of a given header."""

from __future__ import annotations

import numpy as np

from common.messages import DepthFrame, Header


def flat_depth(
    header: Header,
    width: int,
    height: int,
    metres: float,
    *,
    holes: tuple[slice, slice] | None = None,
    hfov_fx: float | None = None,
) -> DepthFrame:
    """A 16UC1 (mm) depth frame of ``width`` x ``height`` reading ``metres`` everywhere but
    ``holes`` (rows, columns: 0, no reading), with ``header`` (its colour frame's); the focal
    length ``hfov_fx`` (default: a 60 deg horizontal field of view), the principal point at
    the centre, a sensor range of 0.2..10 m."""
    mm = np.full((height, width), round(metres * 1000), np.uint16)
    if holes is not None:
        mm[holes] = 0
    fx = hfov_fx if hfov_fx is not None else (width / 2) / float(np.tan(np.radians(30)))
    return DepthFrame(
        header=header,
        encoding="16UC1",
        width=width,
        height=height,
        data=mm.astype("<u2").tobytes(),
        fx=fx,
        fy=fx,
        cx=width / 2,
        cy=height / 2,
        range_min_m=0.2,
        range_max_m=10.0,
    )
