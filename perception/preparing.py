"""Model preparation ahead of serving: every file a spec needs, built where it is missing.

:func:`prepare_for` does every preparation a spec needs, with progress: the default model
fetched and converted, rebuilt at the input size, the INT8 model quantized, and, for the fast
profile, the variants measured and the chosen one prepared (``zstack prepare``). Ctrl-C or
SIGTERM stops it at once, leaving no file half-written (modelprep writes through scratch
files). Serving never imports this module: it opens what was prepared (loading.py), and so
never reaches the quantizer (tests/unit/test_imports.py checks it).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from common.lifecycle import Progress, print_progress
from modelprep.files import ensure_default_model
from modelprep.quantize import QuantizationFailed, quantized_model
from perception.fast_profile import Measure, choose_fast
from perception.pipeline import Detector
from perception.settings import DetectorSpec, ModelSpec
from perception.variants import Prepared, load_plan, named_model, on_fp32, open_as


def sized_model(s: ModelSpec, progress: Progress = print_progress) -> Path:
    """The model file at ``s.imgsz``: the default model (rebuilt for that size when needed), or
    ``s.model``, whose fixed input must then be that size (ConfigError otherwise)."""
    if not s.model:
        return ensure_default_model(progress=progress, imgsz=s.imgsz)
    return named_model(s)


def finds_objects(reference: Path, backend: str) -> Callable[[Path], str | None]:
    """A check for an INT8 model: on the calibration photos it must find something wherever
    the FP32 ``reference`` does (a quantization that wiped the scores finds nothing)."""

    def check(candidate: Path) -> str | None:
        from modelprep.calibration import calibration_photos

        photos = [image for label, image in calibration_photos() if label.endswith(":full")]
        with (
            Detector.open(reference, backend=backend) as fp32,
            Detector.open(candidate, backend=backend) as int8,
        ):
            expected = sum(1 for p in photos if len(fp32.detect(p)))
            found = sum(1 for p in photos if len(int8.detect(p)) and len(fp32.detect(p)))
        if found < expected:
            return (
                f"it finds nothing on {expected - found} of {expected} photos FP32 finds objects in"
            )
        return None

    return check


def prepare(s: ModelSpec, progress: Progress = print_progress, max_batch: int = 1) -> Prepared:
    """The model, backend and options for ``s`` (profile already resolved), for batches of up
    to ``max_batch`` frames, built now where they are missing: what variants.py's ``locate``
    then finds."""
    model = sized_model(s, progress)
    options, runtime = load_plan(s, max_batch)
    if runtime is None:
        return Prepared(model, s.backend, options)
    calibration_dir = Path(s.calibration_dir) if s.calibration_dir else None
    try:
        quantized = quantized_model(
            model,
            runtime=runtime,
            calibration_dir=calibration_dir,
            check=finds_objects(model, s.backend),
            progress=progress,
        )
    except QuantizationFailed as exc:
        return on_fp32(model, s, options, exc)
    return Prepared(quantized, s.backend, options)


def open_prepared(
    s: DetectorSpec, progress: Progress = print_progress, max_batch: int = 1
) -> tuple[Detector, str]:
    """The Detector for ``s`` (profile already resolved), for batches of up to ``max_batch``
    frames, built first where needed (:func:`prepare`), and its note."""
    return open_as(s, prepare(s, progress, max_batch))


def prepare_for(
    s: DetectorSpec, progress: Progress = print_progress, *, measure: Measure | None = None
) -> tuple[Prepared, str]:
    """Prepare what serving ``s`` loads; what it loads, and why that variant ("" unless the
    fast profile chose it). ``measure`` times the fast profile's candidates when their figures
    are not cached (NotPrepared without it)."""
    why = ""
    if s.profile == "fast":
        variant, why = choose_fast(s, progress, measure=measure)
        progress(why)
        s = variant.settings(s)
    return prepare(s, progress), why
