"""How the distances of two runs differ: for each pair of matched detections (compare.py's
matching), the difference of their ``distance_m`` columns (perception/depth.py: the distance
from the camera, NaN where unknown). Pure.

A run made without depth has no ``distance_m`` column at all: its detections count as having
no distance, and a report of two such runs has no distance section.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.messages import Detections

#: The distance column (perception/depth.py's DISTANCE; tools import only perception's
#: public API, tests/unit/recorder checks the two agree).
DISTANCE = "distance_m"


@dataclass(slots=True)
class DistanceFigures:
    """Over the matched detections: the differences B - A where both have a distance (m), and
    how many have one in A only, in B only, in neither."""

    diffs: list[float] = field(default_factory=list)
    only_a: int = 0
    only_b: int = 0
    neither: int = 0
    # Whether either run carried distances at all (its detections had the column).
    present: bool = False

    @property
    def abs_diffs(self) -> npt.NDArray[np.float64]:
        return np.abs(np.asarray(self.diffs, np.float64))

    def add(self, a: Detections, b: Detections, pairs: list[tuple[int, int, float]]) -> None:
        """Count the matched ``pairs`` (i in a, j in b) of one frame."""
        da, db = distances(a), distances(b)
        self.present = self.present or da is not None or db is not None
        for i, j, _iou in pairs:
            ha = da is not None and bool(np.isfinite(da[i]))
            hb = db is not None and bool(np.isfinite(db[j]))
            if ha and hb:
                assert da is not None and db is not None
                self.diffs.append(float(db[j]) - float(da[i]))
            elif ha:
                self.only_a += 1
            elif hb:
                self.only_b += 1
            else:
                self.neither += 1


def distances(d: Detections) -> npt.NDArray[np.float64] | None:
    """The detections' distances (NaN: unknown), None when they carry no distance column."""
    values = d.boxes.columns.get(DISTANCE)
    return None if values is None else np.asarray(values, np.float64)


def report_lines(f: DistanceFigures) -> list[str]:
    """The report's distance section; nothing when neither run carried distances."""
    if not f.present:
        return []
    paired = len(f.diffs)
    if paired:
        ad = f.abs_diffs
        spread = (
            f"|B - A| median **{np.median(ad):.3f} m**, p95 {np.percentile(ad, 95):.3f} m, "
            f"max {np.max(ad):.3f} m (B - A median {np.median(f.diffs):+.3f} m)."
        )
    else:
        spread = "no matched detection has a distance in both runs."
    return [
        "## Distances",
        "",
        f"Matched detections with a distance in both runs: {paired}: {spread}",
        f"With a distance in A only: {f.only_a}; in B only: {f.only_b}; in neither: {f.neither}.",
        "",
    ]
