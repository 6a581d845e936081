"""``benchmark``: time each stage on one or more backends, and score their agreement.

Every backend named with ``--backend`` (repeatable) is loaded once; then one loop runs them all,
round after round, rotating which goes first, so that machine noise (a cron job, a thermal
throttle) lands on every backend alike instead of on whichever ran last. Each round, each
backend does a full ``detect`` and a bare ``backend.infer`` on the same preprocessed tensor,
alternating which of the two goes first.

Agreement: every backend's detections on a set of photos are scored against the FP32 ONNX
Runtime output on the same photos, taken as ground truth (:mod:`.agreement`). The reference
keeps the deployed threshold (``--conf``); candidates are run at :data:`CANDIDATE_CONF` so
that a box scored 0.249 instead of 0.251 still counts as found, as COCO evaluation expects.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.clock import ms_since, perf_s
from common.contracts import BackendBenchmark, BenchmarkReport
from common.errors import ConfigError, ImageError
from common.images import list_images, load_image, load_sample
from common.machine import cpu_model
from perception import DetectionResult, Detector

STAGES = ("preprocess", "inference", "postprocess", "total")
#: scikit-image photos scored for agreement when no ``--images`` folder is given.
SAMPLE_IMAGES = ("astronaut", "camera", "chelsea", "coffee", "motorcycle", "rocket")
#: Candidates' score threshold in the agreement pass: low, so the PR curve is complete.
CANDIDATE_CONF = 0.001
REFERENCE = "onnx"  # ONNX Runtime on the CPU runs the model as exported: FP32 for ours


@dataclass(frozen=True, slots=True, kw_only=True)
class BenchmarkOptions:
    """What ``benchmark`` was asked: the model, the backends (empty: the reference alone), the
    rounds, the image timed and the photos scored, the reference's threshold, the output; or,
    with ``variants``, the backend:precision:size variants to compare instead."""

    model: str | None
    backends: tuple[str, ...]
    runs: int
    warmup: int
    image: str | None  # None: scikit-image chelsea
    images: str | None  # None: the six scikit-image photos of SAMPLE_IMAGES
    conf: float
    as_json: bool
    variants: str | None


def machine() -> dict[str, Any]:
    """What the numbers were measured on."""
    return {
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
    }


def _sample(name: str) -> npt.NDArray[np.uint8]:
    """A scikit-image photo as BGR, by its name in scikit-image (``camera``, not ``cameraman``)."""
    return load_sample("cameraman" if name == "camera" else name)


def agreement_images(folder: str | None) -> list[tuple[str, npt.NDArray[np.uint8]]]:
    """``(label, BGR image)`` pairs: the folder's images, or the scikit-image samples."""
    if folder is None:
        return [(f"skimage:{name}", _sample(name)) for name in SAMPLE_IMAGES]
    paths = list_images([folder])
    if not paths:
        raise ImageError(f"no images found in {folder}")
    return [(str(p), load_image(p)) for p in paths]


class _Timings:
    """Samples of one backend: each stage of the detect call, and the bare run."""

    def __init__(self) -> None:
        self.stages: dict[str, list[float]] = {k: [] for k in STAGES}
        self.bare: list[float] = []

    def add(self, result: DetectionResult, total_ms: float, bare_ms: float) -> None:
        self.bare.append(bare_ms)
        self.stages["preprocess"].append(result.timing.preprocess_ms)
        self.stages["inference"].append(result.timing.inference_ms)
        self.stages["postprocess"].append(result.timing.postprocess_ms)
        self.stages["total"].append(total_ms)

    def report(self, det: Detector) -> BackendBenchmark:
        p50 = {k: round(float(np.percentile(v, 50)), 3) for k, v in self.stages.items()}
        bare = float(np.median(self.bare))
        return {
            "p50_ms": p50,
            "p95_ms": {k: round(float(np.percentile(v, 95)), 3) for k, v in self.stages.items()},
            "fps": round(1e3 / p50["total"], 2),
            "bare_run_p50_ms": round(bare, 3),
            "ratio_to_bare_run": round(p50["total"] / bare, 4),
            "pre_post_fraction_of_inference": round(
                (p50["preprocess"] + p50["postprocess"]) / p50["inference"], 4
            ),
            "backend": {
                "name": det.backend.name,
                "device": det.backend.device,
                "precision": det.backend.precision,
                "threads": getattr(det.backend, "threads", None),
            },
        }


def _one_round(det: Detector, image: npt.NDArray[np.uint8], bare_input: Any, first: bool) -> Any:
    """One detect call and one bare run, in the order ``first`` says."""

    def timed_detect() -> tuple[DetectionResult, float]:
        t0 = perf_s()
        result = det.detect(image)
        return result, ms_since(t0)

    def timed_bare() -> float:
        t0 = perf_s()
        det.backend.infer(bare_input)
        return ms_since(t0)

    if first:
        result, total_ms = timed_detect()
        return result, total_ms, timed_bare()
    bare_ms = timed_bare()
    result, total_ms = timed_detect()
    return result, total_ms, bare_ms


def _detect_all(
    det: Detector, images: Sequence[npt.NDArray[np.uint8]], conf: float
) -> list[DetectionResult]:
    """Detections at threshold ``conf`` (the detector's own settings are put back after)."""
    saved = det.settings
    det.settings = dataclasses.replace(saved, conf=conf)
    try:
        return [det.detect(image) for image in images]
    finally:
        det.settings = saved


def run(options: BenchmarkOptions, resolve_model: Callable[[str | None], Path]) -> int:
    """Time every requested backend in one interleaved loop, then score agreement."""
    if options.variants:
        from tools.benchmarks.variants import run_variants

        return run_variants(
            options.variants,
            model=options.model,
            conf=options.conf,
            runs=options.runs,
            warmup=options.warmup,
            as_json=options.as_json,
        )
    if options.runs < 1 or options.warmup < 0:
        raise ConfigError(
            f"--runs must be >= 1 and --warmup >= 0, got {options.runs}, {options.warmup}"
        )
    if not 0 <= options.conf <= 1:
        raise ConfigError(f"--conf must be a number in [0, 1], got {options.conf}")
    # Imported here: the variants comparison above does without it.
    from tools.evaluation.agreement import score

    labels = list(dict.fromkeys(options.backends or [REFERENCE]))  # repeated names run once
    image = load_image(options.image) if options.image else _sample("chelsea")
    photos = agreement_images(options.images)
    model = resolve_model(options.model)
    with ExitStack() as stack:
        dets = {name: stack.enter_context(Detector.open(model, backend=name)) for name in labels}
        timings = {name: _Timings() for name in labels}
        bare_inputs = {name: det.preprocess([image])[0].copy() for name, det in dets.items()}
        for i in range(options.warmup + options.runs):
            for k in range(len(labels)):  # rotate the start so no backend always runs first
                name = labels[(i + k) % len(labels)]
                result, total_ms, bare_ms = _one_round(
                    dets[name], image, bare_inputs[name], i % 2 == 0
                )
                if i >= options.warmup:
                    timings[name].add(result, total_ms, bare_ms)
        reports = {name: timings[name].report(dets[name]) for name in labels}
        ref = next(
            (
                d
                for d in dets.values()
                if d.backend.name == REFERENCE and d.backend.precision == "fp32"
            ),
            None,
        ) or stack.enter_context(Detector.open(model, backend=REFERENCE))
        pictures = [img for _, img in photos]
        truth = _detect_all(ref, pictures, options.conf)
        for name, det in dets.items():
            reports[name]["agreement"] = score(
                truth, _detect_all(det, pictures, CANDIDATE_CONF)
            ).as_dict()
        first = dets[labels[0]]
        report: BenchmarkReport = {
            **reports[labels[0]],
            "runs": options.runs,
            "warmup": options.warmup,
            "model": {
                "path": str(model),
                "family": first.info.family.value,
                "input": [first.info.input_height, first.info.input_width],
            },
            "image": {
                "path": options.image or "skimage:chelsea",
                "width": image.shape[1],
                "height": image.shape[0],
            },
            "agreement_reference": {
                "backend": f"{ref.backend.name}/{ref.backend.device}/{ref.backend.precision}",
                "conf": options.conf,
                "candidate_conf": CANDIDATE_CONF,
                "images": [label for label, _ in photos],
            },
            "backends": reports,
            "machine": machine(),
        }
    print(json.dumps(report) if options.as_json else format_table(reports))
    return 0


def format_table(reports: dict[str, BackendBenchmark]) -> str:
    """The side-by-side text report: one row per backend."""
    head = f"{'backend':<10}{'device':<9}{'prec':<6}"
    head += (
        "".join(f"{s + ' p50/p95 ms':>24}" for s in STAGES)
        + f"{'fps':>9}{'mAP50':>8}{'mAP50-95':>10}"
    )
    lines = [head]
    for name, r in reports.items():
        b, agree = r["backend"], r["agreement"]
        row = f"{name:<10}{b['device']:<9}{b['precision']:<6}"
        row += "".join(f"{r['p50_ms'][s]:>15.2f} / {r['p95_ms'][s]:<6.2f}" for s in STAGES)
        row += f"{r['fps']:>9.1f}{agree['map50']:>8.3f}{agree['map50_95']:>10.3f}"
        lines.append(row)
    return "\n".join(lines)
