"""``benchmark --variants``: compare (backend, precision, input size) variants side by side.

Every variant is prepared (rebuilt at its size, quantized, cached) and loaded once; then one
loop times a full ``detect`` of each, round after round, in a freshly shuffled order every
round, so that noise from other processes falls on all of them alike. For each: p50 and p95,
the ratio of its p50 to FP32 ONNX Runtime at 640 (always measured, as the reference), AP50 on
the hand-labelled photos, and agreement with the reference: the share of the reference's boxes
(at the deployed threshold) that the variant finds again, same class, IoU >= 0.5.
"""

from __future__ import annotations

import json
import random
from contextlib import ExitStack
from typing import Any

import numpy as np

from common.clock import ms_since, perf_s
from common.errors import ConfigError
from common.images import SAMPLES, load_sample
from common.lifecycle import print_progress
from perception import Variant, open_prepared, variant_of
from services.detector.contract import DetectorSettings

REFERENCE = Variant("onnx", "fp32", 640)


def parse_variants(text: str) -> list[Variant]:
    """``onnx:fp32:640,onnx:int8:480`` -> variants, the reference added first if missing."""
    variants = [Variant.parse(item) for item in text.split(",") if item.strip()]
    if not variants:
        raise ConfigError("--variants needs at least one backend:precision:size")
    return list(dict.fromkeys([REFERENCE, *variants]))


def run_variants(
    spec: str, *, model: str | None, conf: float, runs: int, warmup: int, as_json: bool
) -> int:
    """Time, score and print every variant of ``spec`` (``--variants``): ``warmup`` untimed
    rounds, then ``runs`` timed ones; one JSON object with ``as_json``, else a table."""
    from tools.evaluation.labelled_set import labelled_ap50, matched_boxes

    if runs < 1 or warmup < 0:
        raise ConfigError(f"--runs must be >= 1 and --warmup >= 0, got {runs}, {warmup}")
    variants = parse_variants(spec)
    base = DetectorSettings(model=model or "", conf=conf)
    image = load_sample("chelsea")
    photos = [load_sample(name) for name in SAMPLES]
    rows: dict[str, dict[str, Any]] = {}
    with ExitStack() as stack:
        dets = {}
        for v in variants:
            det, note = open_prepared(v.settings(base), print_progress)
            stack.enter_context(det)
            dets[v.label] = det
            rows[v.label] = {"runs_as": variant_of(det), "note": note}
        times: dict[str, list[float]] = {label: [] for label in dets}
        order = list(dets)
        print_progress(f"benchmark: {len(order)} variants, {warmup}+{runs} rounds")
        for i in range(warmup + runs):
            random.shuffle(order)
            for label in order:
                t0 = perf_s()
                dets[label].detect(image)
                if i >= warmup:
                    times[label].append(ms_since(t0))
        reference = [dets[REFERENCE.label].detect(p) for p in photos]
        ref_p50 = float(np.percentile(times[REFERENCE.label], 50))
        for label, det in dets.items():
            matched, total = matched_boxes(reference, [det.detect(p) for p in photos])
            p50 = float(np.percentile(times[label], 50))
            rows[label].update(
                p50_ms=round(p50, 2),
                p95_ms=round(float(np.percentile(times[label], 95)), 2),
                ratio=round(p50 / ref_p50, 3),
                ap50=round(labelled_ap50(det), 4),
                agreement=[matched, total],
            )
    from common.machine import machine_info

    report = {"runs": runs, "warmup": warmup, "variants": rows, "machine": machine_info()}
    print(json.dumps(report) if as_json else format_rows(rows))
    return 0


def format_rows(rows: dict[str, dict[str, Any]]) -> str:
    """One line per variant."""
    lines = [f"{'variant':<20}{'p50 ms':>9}{'p95 ms':>9}{'ratio':>7}{'AP50':>7}{'agree':>9}  note"]
    for label, r in rows.items():
        matched, total = r["agreement"]
        lines.append(
            f"{label:<20}{r['p50_ms']:>9.1f}{r['p95_ms']:>9.1f}{r['ratio']:>7.2f}"
            f"{r['ap50']:>7.3f}{f'{matched}/{total}':>9}  {r['note']}"
        )
    print_progress("benchmark: the machine is shared: repeat runs to see the noise")
    return "\n".join(lines)
