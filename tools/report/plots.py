"""The report's PNG plots, drawn with matplotlib's object API (no pyplot, no global state).

``Figure.savefig`` renders with the Agg canvas, so no display and no backend setting are needed,
and nothing here is shared between threads or calls. Each function takes plain session data
(lists of milliseconds, the timeline columns, benchmark JSON) and writes one small PNG.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from common.contracts import BackendBenchmark, TimelineSeries

DPI = 100
SIZE = (8.0, 4.5)  # inches: 800 x 450 px at DPI

#: The parts one frame's end-to-end time splits into, in order, with what each one covers.
SEGMENTS: tuple[tuple[str, str], ...] = (
    ("transport", "capture -> the frame reached the detector (the bus)"),
    ("wait", "in the detector's one-frame mailbox until it was free, frame conversion, send"),
    ("preprocess", "letterbox and normalise"),
    ("inference", "the model"),
    ("postprocess", "decode and NMS"),
    ("control", "detections sent -> first command reacting to them"),
)
COLOURS = {
    "transport": "#8c8c8c",
    "preprocess": "#4c72b0",
    "inference": "#dd8452",
    "postprocess": "#55a868",
    "wait": "#c7c7c7",
    "control": "#8172b3",
}
_STAGE_OF = {
    "transport": "capture_to_detector",
    "preprocess": "preprocess",
    "inference": "inference",
    "postprocess": "postprocess",
    "control": "detections_to_command",
}


def _new(figsize: tuple[float, float] = SIZE) -> Figure:
    return Figure(figsize=figsize, dpi=DPI, layout="constrained")


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    return path


def _empty(ax: Axes, what: str) -> None:
    ax.text(0.5, 0.5, f"no {what} recorded", ha="center", va="center", transform=ax.transAxes)
    ax.set_xticks([])
    ax.set_yticks([])


def latency_histogram(samples: Mapping[str, Sequence[float]], path: Path) -> Path:
    """End-to-end, capture-to-detections and inference latency as overlaid histograms."""
    fig = _new()
    ax = fig.subplots()
    series = [
        ("end_to_end", "capture \u2192 command", "#c44e52"),
        ("capture_to_detections", "capture \u2192 detections", "#4c72b0"),
        ("inference", "inference alone", "#dd8452"),
    ]
    present = [(k, label, c) for k, label, c in series if len(samples.get(k, ()))]
    if not present:
        _empty(ax, "latency")
    else:
        values = np.concatenate([np.asarray(samples[k], float) for k, _, _ in present])
        bins = np.linspace(0.0, float(np.percentile(values, 99.5)) * 1.05 + 1.0, 41)
        for key, label, colour in present:
            v = np.asarray(samples[key], float)
            p50, p95 = np.percentile(v, [50, 95])
            ax.hist(
                np.clip(v, None, bins[-1]),
                bins=bins.tolist(),
                histtype="stepfilled",
                alpha=0.35,
                color=colour,
                label=f"{label}: p50 {p50:.0f} ms, p95 {p95:.0f} ms",
            )
            ax.axvline(p50, color=colour, linestyle="--", linewidth=1)
        # Below the axes, never over the bars.
        fig.legend(loc="outside lower center", ncols=1, fontsize=9, frameon=False)
        ax.set_xlim(0, bins[-1])
    ax.set_title("Latency per frame (dashed: median)")
    ax.set_xlabel("latency (ms)")
    ax.set_ylabel("frames")
    return _save(fig, path)


def fps_over_time(timeline: TimelineSeries, path: Path) -> Path:
    """Frames offered to the detector, frames it detected on, and frames it dropped, per second."""
    fig = _new()
    ax = fig.subplots()
    t = np.asarray(timeline.get("t", ()), float)
    if t.size == 0:
        _empty(ax, "timeline")
    else:
        t = t - t[0]
        period = float(timeline.get("period_s", 1.0))  # type: ignore[arg-type]
        dropped = np.asarray(timeline["dropped"], float) / period
        offered = np.asarray(timeline["offered_fps"], float)
        fps = np.asarray(timeline["fps"], float)
        edges = np.append(t, t[-1] + period)  # a step per period, the last one drawn in full
        ax.bar(
            t,
            dropped,
            width=period * 0.9,
            align="edge",
            color="#c44e52",
            alpha=0.35,
            label="dropped (a newer frame arrived)",
        )
        ax.stairs(offered, edges, color="#8c8c8c", label="offered to the detector")
        ax.stairs(fps, edges, color="#4c72b0", linewidth=2, label="detected (detections sent)")
        ax.set_xlim(0, edges[-1])
        ax.set_ylim(0, max(float(offered.max()), float(fps.max()), 1.0) * 1.1)
        fig.legend(loc="outside lower center", ncols=3, fontsize=9, frameon=False)
    ax.set_title("Throughput over time")
    ax.set_xlabel("time since the recording started (s)")
    ax.set_ylabel("frames per second")
    return _save(fig, path)


def segment_means(latency_ms: Mapping[str, Mapping[str, float]]) -> dict[str, float]:
    """Mean ms of each segment of :data:`SEGMENTS`; "wait" is the time in the detector outside
    its three timed stages (capture_to_detections minus the rest, never below 0)."""
    mean = {k: float(v.get("mean", 0.0)) for k, v in latency_ms.items()}
    out = {seg: mean.get(stage, 0.0) for seg, stage in _STAGE_OF.items()}
    timed = sum(out[s] for s in ("transport", "preprocess", "inference", "postprocess"))
    out["wait"] = max(mean.get("capture_to_detections", 0.0) - timed, 0.0)
    return {seg: out[seg] for seg, _ in SEGMENTS}


def stage_breakdown(
    latency_ms: Mapping[str, Mapping[str, float]],
    samples: Mapping[str, Sequence[float]],
    path: Path,
) -> Path:
    """Left: the mean frame as a stacked bar of its segments. Right: each stage's spread."""
    fig = _new((10.0, 4.5))
    bar_ax, box_ax = fig.subplots(1, 2, width_ratios=[1, 1.4])
    means = segment_means(latency_ms)
    left = 0.0
    total = sum(means.values())
    for seg, _ in SEGMENTS:
        width = means[seg]
        bar_ax.barh(0, width, left=left, color=COLOURS[seg], label=f"{seg} {width:.1f} ms")
        if total and width / total > 0.08:
            bar_ax.text(left + width / 2, 0, f"{width:.0f}", ha="center", va="center", fontsize=9)
        left += width
    bar_ax.set_yticks([])
    bar_ax.set_ylim(-0.6, 1.6)
    bar_ax.set_xlabel("mean time per frame (ms)")
    bar_ax.set_title(f"Where the time goes: {total:.0f} ms")
    bar_ax.legend(loc="upper center", ncols=2, fontsize=8, frameon=False)
    present = [
        (seg, _STAGE_OF[seg])
        for seg, _ in SEGMENTS
        if seg in _STAGE_OF and len(samples.get(_STAGE_OF[seg], ()))
    ]
    if present:
        parts = box_ax.boxplot(
            [np.asarray(samples[stage], float) for _, stage in present],
            orientation="horizontal",
            whis=(5, 95),
            showfliers=False,
            patch_artist=True,
            tick_labels=[seg for seg, _ in present],
            medianprops={"color": "black"},
        )
        for patch, (seg, _) in zip(parts["boxes"], present, strict=True):
            patch.set_facecolor(COLOURS[seg])
        box_ax.invert_yaxis()
        box_ax.set_xlim(left=0)
    else:
        _empty(box_ax, "stage samples")
    box_ax.set_xlabel("ms (box: p25-p75, whiskers: p5-p95)")
    box_ax.set_title("Spread per stage")
    return _save(fig, path)


def benchmark_label(bench: Mapping[str, Any]) -> str:
    b = bench.get("backend", {})
    return "/".join(str(b.get(k, "?")) for k in ("name", "device", "precision"))


def backend_comparison(benchmarks: Sequence[BackendBenchmark], path: Path) -> Path:
    """Median preprocess / inference / postprocess per backend, stacked; p95 total marked."""
    fig = _new()
    ax = fig.subplots()
    labels = [benchmark_label(b) for b in benchmarks]
    bottom = np.zeros(len(benchmarks))
    for stage in ("preprocess", "inference", "postprocess"):
        values = np.array([float(b["p50_ms"].get(stage, 0.0)) for b in benchmarks])
        ax.bar(labels, values, bottom=bottom, color=COLOURS[stage], label=f"{stage} (p50)")
        bottom += values
    p95 = np.array([float(b.get("p95_ms", {}).get("total", np.nan)) for b in benchmarks])
    ax.scatter(labels, p95, marker="_", s=600, color="black", label="total p95", zorder=3)
    top = float(np.nanmax([*p95, *bottom, 1.0]))
    for x, (total, high) in enumerate(zip(bottom, p95, strict=True)):
        above = np.nanmax([total, high]) + top * 0.02  # clear of the p95 mark
        text = f"p50 {total:.1f} ms" + ("" if np.isnan(high) else f", p95 {high:.1f}")
        ax.text(x, above, text, ha="center", va="bottom", fontsize=9)
    ax.set_ylim(0, top * 1.15)
    ax.set_title("Detector stages by backend (same model and image)")
    ax.set_ylabel("ms per image")
    ax.legend(loc="upper right", fontsize=9)
    return _save(fig, path)
