"""Laser scans for the controller's unit tests."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from common.messages import Header, LaserScan


def scan_of(
    angles: npt.NDArray[np.float64], ranges: npt.NDArray[np.float32], header: Header
) -> LaserScan:
    """A scan whose rays point at ``angles`` (evenly spaced) and read ``ranges``."""
    return LaserScan(
        header=header,
        angle_min=float(angles[0]),
        angle_increment=float(angles[1] - angles[0]),
        range_min=0.05,
        range_max=20.0,
        ranges=ranges,
    )
