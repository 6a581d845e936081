"""The metrics service and accuracy scoring. Exported for the detector's own measurements
(the fast profile, the benchmark): reading a labelled set and scoring detections on it."""

from services.metrics.accuracy import ImageDetections
from services.metrics.datasets import load_dataset
from services.metrics.evaluate import score

__all__ = ["ImageDetections", "load_dataset", "score"]
