"""The detection library: images in, boxes, scores and class ids out (docs/detector.md).

What other packages use is exported here; the modules behind it are the library's own (tools
import only this; tests/unit/test_imports.py checks it). No bus, no service: the detector
service (services/detector/) and the tools are built on it.

    Detector            a model loaded on one backend: ``Detector.open(path, backend=...,
                        settings=DecodeOptions(...))``
    ModelSpec, DecodeOptions, DetectorSpec, TrackerParams
                        the library's settings (``settings.py``): what model to run and how,
                        what to keep of its output, the tracker's thresholds; the detector
                        service's settings (services/detector/contract.py) are these and more
    DetectionResult     what ``Detector.detect`` returns (``StageTiming``: its stage times)
    Tracker             track ids across frames (``tracker_clock``, ``iou_matrix``);
                        ``KalmanTracker`` the Kalman one (``kalman_tracker.py``), which also
                        takes the robot's turn and each box's colour (``appearance``,
                        ``appearance_similarity``); ``new_tracker`` either, by
                        ``TrackerParams.kind`` (``TrackerKind``)
    Variant             ``backend:precision:imgsz``; ``variant_of(detector)`` says what one runs
    prepare_for         every preparation a spec needs, ahead of serving (``zstack prepare``)
    load                open what was prepared, building nothing; NotPrepared says what to run
    prepare, open_prepared, sized_model    one variant's files, built where missing (tools)
    choose_fast         the fast profile's choice (``Figures``, ``Measure``, ``TIMED_RUNS``)
    measure_batch       the batch size that serves frames fastest (``probe_sizes``,
                        ``PROBE_SHAPE``, ``BatchChoice``)
    measure_depth       each box's distance, 3D centre and extent from an aligned depth image
                        (``depth.py``, docs/depth.md: ``depth_metres``, ``Intrinsics``,
                        ``DepthParams``, ``Mounting``, ``Mounted``, ``to_robot``,
                        ``to_depth_pixels``, ``unknown_depth``; column names
                        ``DEPTH_COLUMNS``, ``DEPTH_DISTANCE``, ``DEPTH_CENTRE``, ``DEPTH_SIZE``)

The detection path: ``pipeline.py`` (``preprocess``, a runtimes/ backend, ``decode.py``,
``postprocess.py``) -> ``tracker.py``; ``model_info.py`` reads what a model says of itself.
Model files: ``variants.py`` (a spec -> the file a backend loads, as prepared),
``fast_profile.py``, ``loading.py`` (serving's load: opens what was prepared, and reaches no
quantizer) and ``preparing.py`` (building what is missing: modelprep/, acquire/ and quantize/).

Importing this package imports none of its modules: each name is imported on first use
(``_EXPORTS``), so that what needs one name (the detector's contract, its settings; a service,
``Mounting``) loads only the module behind it. The ``TYPE_CHECKING`` imports below say the same
to type checkers (tests/unit/perception/test_settings.py checks that the two agree).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from perception.batching import PROBE_SHAPE, BatchChoice, probe_sizes
    from perception.batching import measure as measure_batch
    from perception.colour_cue import FEATURES as APPEARANCE_FEATURES
    from perception.colour_cue import Features, appearance
    from perception.colour_cue import similarity as appearance_similarity
    from perception.depth import CENTRE as DEPTH_CENTRE
    from perception.depth import COLUMNS as DEPTH_COLUMNS
    from perception.depth import DISTANCE as DEPTH_DISTANCE
    from perception.depth import SIZE as DEPTH_SIZE
    from perception.depth import (
        DepthParams,
        Intrinsics,
        Mounted,
        Mounting,
        depth_metres,
        to_depth_pixels,
        to_robot,
    )
    from perception.depth import measure as measure_depth
    from perception.depth import unknown as unknown_depth
    from perception.fast_profile import TIMED_RUNS, Figures, Measure, choose_fast
    from perception.kalman_tracker import KalmanTracker, new_tracker
    from perception.loading import load
    from perception.pipeline import Detector
    from perception.preparing import open_prepared, prepare, prepare_for, sized_model
    from perception.settings import (
        DecodeOptions,
        DetectorSpec,
        ModelSpec,
        TrackerKind,
        TrackerParams,
    )
    from perception.tracker import Tracker, iou_matrix, tracker_clock
    from perception.types import DetectionResult, StageTiming
    from perception.variants import PREPARE_COMMAND, NotPrepared, Prepared, Variant, variant_of

#: Module (of this package) -> the names this package exports from it; ``"a as b"`` exports
#: ``a`` as ``b``.
_FROM: dict[str, tuple[str, ...]] = {
    "batching": ("PROBE_SHAPE", "BatchChoice", "probe_sizes", "measure as measure_batch"),
    "depth": (
        "CENTRE as DEPTH_CENTRE",
        "COLUMNS as DEPTH_COLUMNS",
        "DISTANCE as DEPTH_DISTANCE",
        "SIZE as DEPTH_SIZE",
        "DepthParams",
        "Intrinsics",
        "Mounted",
        "Mounting",
        "depth_metres",
        "to_depth_pixels",
        "to_robot",
        "measure as measure_depth",
        "unknown as unknown_depth",
    ),
    "fast_profile": ("TIMED_RUNS", "Figures", "Measure", "choose_fast"),
    "loading": ("load",),
    "pipeline": ("Detector",),
    "preparing": ("open_prepared", "prepare", "prepare_for", "sized_model"),
    "settings": ("DecodeOptions", "DetectorSpec", "ModelSpec", "TrackerKind", "TrackerParams"),
    "colour_cue": (
        "FEATURES as APPEARANCE_FEATURES",
        "Features",
        "appearance",
        "similarity as appearance_similarity",
    ),
    "kalman_tracker": ("KalmanTracker", "new_tracker"),
    "tracker": ("Tracker", "iou_matrix", "tracker_clock"),
    "types": ("DetectionResult", "StageTiming"),
    "variants": ("PREPARE_COMMAND", "NotPrepared", "Prepared", "Variant", "variant_of"),
}
#: Exported name -> (module, its name there).
_EXPORTS: dict[str, tuple[str, str]] = {
    alias.partition(" as ")[2] or alias: (f"{__name__}.{module}", alias.partition(" as ")[0])
    for module, names in _FROM.items()
    for alias in names
}
__all__ = [
    "APPEARANCE_FEATURES",
    "DEPTH_CENTRE",
    "DEPTH_COLUMNS",
    "DEPTH_DISTANCE",
    "DEPTH_SIZE",
    "PREPARE_COMMAND",
    "PROBE_SHAPE",
    "TIMED_RUNS",
    "BatchChoice",
    "DecodeOptions",
    "DepthParams",
    "DetectionResult",
    "Detector",
    "DetectorSpec",
    "Features",
    "Figures",
    "Intrinsics",
    "KalmanTracker",
    "Measure",
    "ModelSpec",
    "Mounted",
    "Mounting",
    "NotPrepared",
    "Prepared",
    "StageTiming",
    "Tracker",
    "TrackerKind",
    "TrackerParams",
    "Variant",
    "appearance",
    "appearance_similarity",
    "choose_fast",
    "depth_metres",
    "iou_matrix",
    "load",
    "measure_batch",
    "measure_depth",
    "new_tracker",
    "open_prepared",
    "prepare",
    "prepare_for",
    "probe_sizes",
    "sized_model",
    "to_depth_pixels",
    "to_robot",
    "tracker_clock",
    "unknown_depth",
    "variant_of",
]


def __getattr__(name: str) -> Any:
    """The exported ``name``, importing its module on first use."""
    try:
        module, attribute = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value  # once imported, found without coming here again
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
