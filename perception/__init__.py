"""The detection library: images in, boxes, scores and class ids out (docs/detector.md).

What other packages use is exported here; the modules behind it are the library's own (tools
import only this; tests/unit/test_imports.py checks it). No bus, no service: the detector
service (services/detector/) and the tools are built on it.

    Detector            a model loaded on one backend: ``Detector.open(path, backend=...,
                        settings=DetectorSettings(...))`` (services/detector/contract.py)
    DetectionResult     what ``Detector.detect`` returns (``StageTiming``: its stage times)
    Tracker             track ids across frames (``tracker_clock``, ``iou_matrix``)
    Variant             ``backend:precision:imgsz``; ``variant_of(detector)`` says what one runs
    prepare_for         every preparation settings need, ahead of serving (``zstack prepare``)
    load                open what was prepared, building nothing; NotPrepared says what to run
    prepare, open_prepared, sized_model    one variant's files, built where missing (tools)
    choose_fast         the fast profile's choice (``Figures``, ``Measure``, ``TIMED_RUNS``)
    measure_batch       the batch size that serves frames fastest (``probe_sizes``,
                        ``PROBE_SHAPE``, ``BatchChoice``)
    measure_depth       each box's distance, 3D centre and extent from an aligned depth image
                        (``depth.py``, docs/depth.md: ``depth_metres``, ``Intrinsics``,
                        ``DepthParams``, ``Mounting``, ``to_robot``, ``to_depth_pixels``,
                        ``unknown_depth``; column names ``DEPTH_COLUMNS``, ``DEPTH_DISTANCE``,
                        ``DEPTH_CENTRE``, ``DEPTH_SIZE``)

The detection path: ``pipeline.py`` (``preprocess``, a runtimes/ backend, ``decode.py``,
``postprocess.py``) -> ``tracker.py``; ``model_info.py`` reads what a model says of itself.
Model files: ``variants.py`` (settings -> the file a backend loads), ``fast_profile.py``,
``loading.py``; building them is modelprep/ (acquire/, quantize/), imported only to build.
"""

from perception.batching import PROBE_SHAPE, BatchChoice, probe_sizes
from perception.batching import measure as measure_batch
from perception.depth import CENTRE as DEPTH_CENTRE
from perception.depth import COLUMNS as DEPTH_COLUMNS
from perception.depth import DISTANCE as DEPTH_DISTANCE
from perception.depth import SIZE as DEPTH_SIZE
from perception.depth import (
    DepthParams,
    Intrinsics,
    Mounting,
    depth_metres,
    to_depth_pixels,
    to_robot,
)
from perception.depth import measure as measure_depth
from perception.depth import unknown as unknown_depth
from perception.fast_profile import TIMED_RUNS, Figures, Measure, choose_fast
from perception.loading import load, prepare_for
from perception.pipeline import Detector
from perception.tracker import Tracker, iou_matrix, tracker_clock
from perception.types import DetectionResult, StageTiming
from perception.variants import (
    PREPARE_COMMAND,
    NotPrepared,
    Prepared,
    Variant,
    open_prepared,
    prepare,
    sized_model,
    variant_of,
)

__all__ = [
    "DEPTH_CENTRE",
    "DEPTH_COLUMNS",
    "DEPTH_DISTANCE",
    "DEPTH_SIZE",
    "PREPARE_COMMAND",
    "PROBE_SHAPE",
    "TIMED_RUNS",
    "BatchChoice",
    "DepthParams",
    "DetectionResult",
    "Detector",
    "Figures",
    "Intrinsics",
    "Measure",
    "Mounting",
    "NotPrepared",
    "Prepared",
    "StageTiming",
    "Tracker",
    "Variant",
    "choose_fast",
    "depth_metres",
    "iou_matrix",
    "load",
    "measure_batch",
    "measure_depth",
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
