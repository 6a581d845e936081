"""The comparison's PNG: latency per stage of both runs side by side, the matched boxes' IoU,
and (when the runs carried distances) how far apart the matched boxes' distances are.

Drawn with matplotlib's object API and the Agg canvas (as tools/report/plots.py): no
display, no global state.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from tools.compare.compare import Comparison

DPI = 100
COLOURS = ("#4c72b0", "#dd8452")  # A, B


def comparison_plot(c: Comparison, name_a: str, name_b: str, path: Path) -> Path:
    depth = bool(c.distances.diffs)
    fig = Figure(figsize=(13.0 if depth else 10.0, 4.5), dpi=DPI, layout="constrained")
    lat, hist, *rest = fig.subplots(1, 3 if depth else 2, width_ratios=(2, 1, 1)[: 2 + depth])
    stages = list(c.latency_ms)
    x = np.arange(len(stages))
    for k, (name, colour) in enumerate(zip((name_a, name_b), COLOURS, strict=True)):
        p50 = [float(np.percentile(c.latency_ms[s][k], 50)) if c.latency_ms[s][k] else 0.0
               for s in stages]  # fmt: skip
        lat.bar(x + (k - 0.5) * 0.4, p50, width=0.4, color=colour, label=name)
    lat.set_xticks(x, [s.replace("_", " ") for s in stages], rotation=25, ha="right", fontsize=8)
    lat.set_ylabel("p50 latency (ms)")
    lat.set_title("Latency per stage")
    # Below the axes, never over the bars.
    fig.legend(loc="outside lower center", ncols=2, fontsize=9, frameon=False)
    if c.ious:
        hist.hist(c.ious, bins=np.linspace(c.iou_min, 1.0, 21).tolist(), color="#55a868")
    else:
        hist.text(0.5, 0.5, "no matched detections", ha="center", va="center",
                  transform=hist.transAxes)  # fmt: skip
    # On two lines: the narrow right panel cut a one-line title off.
    hist.set_title(f"IoU of matched detections\n({c.matched} of {max(c.detections)})")
    hist.set_xlabel("IoU")
    hist.set_ylabel("detections")
    if rest:
        (dist,) = rest
        diffs = c.distances.abs_diffs
        # From 0: the axis shows how far apart in metres, never an offset around one value.
        top = max(0.05, float(diffs.max())) * 1.05
        dist.hist(diffs, bins=np.linspace(0.0, top, 21).tolist(), color="#8172b3")
        dist.set_title(f"|distance B - A| of matched\n({len(c.distances.diffs)} with both)")
        dist.set_xlabel("m")
        dist.set_ylabel("detections")
    fig.savefig(path, dpi=DPI)
    return path
