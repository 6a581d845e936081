"""The detector: images in, boxes, scores and class ids out (docs/detector.md).

What other packages may use is exported here; the modules behind it are the detector's own.

    Detector               a model loaded on one backend: ``Detector.open(path, backend=...,
                           settings=DetectorSettings(...))`` (from common.settings)
    DetectionResult        what ``Detector.detect`` returns
    ensure_default_model   the default model's path, fetched and converted first if needed

The detection path: ``service.py`` (the Zenoh I/O) -> ``pipeline.py`` (``preprocess``,
``backends/``, ``decode``, ``postprocess``) -> ``tracker.py``. Model acquisition lives in
``acquire/`` and the CUDA backend's ONNX interpreter in ``onnx_torch/``; neither is imported on
the CPU path.
"""

from modelprep.files import ensure_default_model
from services.detector.pipeline import Detector
from services.detector.types import DetectionResult

__all__ = ["DetectionResult", "Detector", "ensure_default_model"]
