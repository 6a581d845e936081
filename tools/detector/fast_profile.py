"""Measuring the fast profile: every candidate variant timed and scored on the labelled photos.

The detector service only reads the cached choice (perception/fast_profile.py); this is
what ``zstack prepare`` (and ``zstack fast-profile``) runs ahead of time.
"""

from __future__ import annotations

import random
from collections.abc import Sequence

import numpy as np

from common.clock import ms_since, perf_s
from common.images import load_sample
from common.lifecycle import Progress
from perception import TIMED_RUNS, DetectorSpec, Figures, Variant, open_prepared
from tools.evaluation.labelled_set import labelled_ap50


def measure(
    s: DetectorSpec, variants: Sequence[Variant], progress: Progress, runs: int = TIMED_RUNS
) -> list[Figures]:
    """Time and score every variant; one whose INT8 build fell back to FP32 is left out."""
    image = load_sample("chelsea")
    dets, ap50 = {}, {}
    try:
        for v in variants:
            progress(f"fast profile: preparing {v.label}")
            det, note = open_prepared(v.settings(s), progress)
            if note:
                det.close()
                continue
            dets[v.label] = det
            ap50[v.label] = labelled_ap50(det)
            det.detect(image)  # warm-up
        times: dict[str, list[float]] = {label: [] for label in dets}
        order = list(dets)
        progress(f"fast profile: timing {len(order)} variants, {runs} rounds")
        for _ in range(runs):
            random.shuffle(order)
            for label in order:
                t0 = perf_s()
                dets[label].detect(image)
                times[label].append(ms_since(t0))
    finally:
        for det in dets.values():
            det.close()
    return [Figures(k, round(float(np.median(times[k])), 2), round(ap50[k], 4)) for k in dets]
