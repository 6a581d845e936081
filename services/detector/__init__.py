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

from typing import TYPE_CHECKING

from common.lazy import exports

if TYPE_CHECKING:
    from modelprep.files import ensure_default_model
    from services.detector.pipeline import Detector
    from services.detector.types import DetectionResult

__all__ = ["DetectionResult", "Detector", "ensure_default_model"]
# Imported on first use: the detector's contract (services/detector/contract.py) loads no model
# code.
__getattr__ = exports(
    __name__,
    {
        "DetectionResult": "services.detector.types",
        "Detector": "services.detector.pipeline",
        "ensure_default_model": "modelprep.files",
    },
)
