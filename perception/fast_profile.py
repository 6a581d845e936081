"""The fast profile: the fastest variant that keeps accuracy on the labelled photos.

Candidates are every variant this machine can run: ONNX Runtime FP32 and INT8 at 640, 512, 480
and 416, and the same on OpenVINO when that backend is installed. Each is timed (interleaved,
round-robin in a shuffled order) and scored (AP50 on the hand-labelled photos); the choice is
the fastest at p50 whose AP50 is at most ``fast_max_ap50_drop`` below FP32 at 640
(:func:`choose`, pure). Measuring takes a minute or more, so it is a step of model preparation,
run ahead of time (``zstack prepare``, which ``make run`` runs; ``zstack fast-profile`` measures
alone), which prints its progress and stops at once on Ctrl-C or SIGTERM, leaving nothing
half-written. The figures are cached beside the model, keyed by the model's sha256, the CPU
(model and flags), the candidates and the calibration folder. The detector service only reads
the cache: it never measures at start-up (a supervisor with a deadline would kill it midway);
with no cache it stops with one line saying what to run. The choice is logged in one line.
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from common.errors import BackendUnavailable, ConfigError
from common.files import atomic_write_bytes, sha256_file
from common.lifecycle import Progress, print_progress
from common.machine import cpu_model
from modelprep.files import ensure_default_model
from perception.settings import DetectorSpec, ModelSpec
from perception.variants import NotPrepared, Variant, located_model, model_input_hw
from runtimes.table import BACKENDS, import_backend

log = logging.getLogger("perception.fast_profile")

SIZES = (640, 512, 480, 416)
TIMED_RUNS = 20
FORMAT = 1


@dataclass(frozen=True, slots=True)
class Figures:
    """One measured variant: its label, p50 time of a full detect, AP50 on the labelled set."""

    variant: str
    p50_ms: float
    ap50: float


def choose(figures: Sequence[Figures], reference: str, max_drop: float) -> tuple[str, str]:
    """``(chosen variant, one line saying why)``: the fastest whose AP50 is within
    ``max_drop`` of ``reference``'s. ConfigError when the reference was not measured."""
    by_name = {f.variant: f for f in figures}
    ref = by_name.get(reference)
    if ref is None:
        raise ConfigError(f"fast profile: the reference {reference} was not measured")
    keeps = [f for f in figures if f.ap50 >= ref.ap50 - max_drop - 1e-9]
    best = min(keeps, key=lambda f: f.p50_ms)
    faster_lost = sorted(
        (f for f in figures if f.p50_ms < best.p50_ms and f not in keeps), key=lambda f: f.p50_ms
    )
    why = (
        f"fast profile: {best.variant} (p50 {best.p50_ms:.1f} ms, "
        f"{best.p50_ms / ref.p50_ms:.2f}x of {reference}'s {ref.p50_ms:.1f} ms; "
        f"AP50 {best.ap50:.3f} vs {ref.ap50:.3f}, allowed drop {max_drop:g})"
    )
    if faster_lost:
        lost = ", ".join(f"{f.variant} AP50 {f.ap50:.3f}" for f in faster_lost)
        why += f"; faster but less accurate: {lost}"
    return best.variant, why


def candidates(sizes: Sequence[int] = SIZES) -> list[Variant]:
    """Every variant this machine can run at ``sizes``, FP32 ONNX at the first size first."""
    backends = ["onnx"]
    if "openvino" in BACKENDS:
        try:
            import_backend("openvino")
            backends.append("openvino")
        except BackendUnavailable as exc:
            log.info("fast profile: no openvino candidates (%s)", exc)
    return [Variant(b, p, size) for b in backends for size in sizes for p in ("fp32", "int8")]


def sizes_for(s: ModelSpec) -> tuple[int, ...]:
    """SIZES for the default model; a named model only runs at its own fixed size."""
    if not s.model:
        return SIZES
    height, width = model_input_hw(Path(s.model))
    if height is None or height != width:
        raise ConfigError(
            f"fast profile: {s.model} needs a fixed square input, has {height}x{width}"
        )
    return (height,)


def cpu_flags() -> str:
    """The CPU's feature flags (Linux), sorted; "" elsewhere."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return " ".join(sorted(line.split(":", 1)[1].split()))
    except OSError:
        return ""
    return ""


def cache_key(s: ModelSpec, variants: Sequence[Variant], model: Path) -> dict[str, object]:
    """What the measured figures for ``model`` (the base model ``s`` names) depend on."""
    return {
        "format": FORMAT,
        "model_sha256": sha256_file(model),
        "cpu": cpu_model(),
        "cpu_flags": hashlib.sha256(cpu_flags().encode()).hexdigest()[:16],
        "candidates": [v.label for v in variants],
        "calibration_dir": s.calibration_dir,
    }


def cache_file(model: Path) -> Path:
    """Where the figures measured for ``model`` are cached."""
    return model.with_name(model.stem + ".fast-profile.json")


#: Times and scores variants: (spec, variants, progress) -> their figures. The one that
#: does it is a tool (tools/detector/fast_profile.py); the detector service never measures.
Measure = Callable[[DetectorSpec, Sequence[Variant], Progress], list[Figures]]


def choose_fast(
    s: DetectorSpec, progress: Progress = print_progress, *, measure: Measure | None = None
) -> tuple[Variant, str]:
    """The fast profile's variant for ``s`` and why: measured now when ``measure`` is given and
    nothing is cached (the default model fetched first); without ``measure``, from the cache
    alone (NotPrepared, one line saying what to run, when the model or the figures are
    missing)."""
    if s.model:
        model = Path(s.model)
    elif measure is not None:
        model = ensure_default_model(progress=progress)
    else:
        model = located_model(ModelSpec())  # the default model, as prepared
    variants = candidates(sizes_for(s))
    reference = variants[0].label
    key = cache_key(s, variants, model)
    path = cache_file(model)
    figures: list[Figures] | None = None
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
        if stored.get("key") == key:
            figures = [Figures(**f) for f in stored["figures"]]
    except (OSError, ValueError, TypeError, KeyError):
        figures = None
    source = "cached figures"
    if figures is None:
        if measure is None:
            raise NotPrepared(
                f'detector.profile = "fast" has not been measured for {model.stem} on this CPU '
                '(it takes a minute or two; or set profile = "default")'
            )
        progress(f"fast profile: measuring {len(variants)} variants (once; cached in {path.name})")
        figures = measure(s, variants, progress)
        record = {"key": key, "figures": [asdict(f) for f in figures]}
        atomic_write_bytes(path, json.dumps(record, indent=2).encode())
        source = "measured now"
    label, why = choose(figures, reference, s.fast_max_ap50_drop)
    why = f"{why} [{source}]"
    log.info("%s", why)
    return Variant.parse(label), why
