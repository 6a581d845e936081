"""The cuda backend on the real default model: on CPU against ONNX Runtime, on a GPU end to end.

The ``gpu`` tests are skipped, with the reason, where PyTorch sees no CUDA device.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
import torch
from skimage import data

from perception.pipeline import Detector
from perception.types import DetectionResult
from runtimes import BACKENDS
from runtimes import cuda as cuda_backend
from runtimes.onnx import OnnxBackend

pytestmark = pytest.mark.integration

CONFIDENT = 0.4  # a detection this sure must be found by both backends (the threshold is 0.25)
MIN_IOU = 0.9
SCORE_TOLERANCE = {"fp32": 0.01, "fp16": 0.03}


def _no_cuda_reason() -> str:
    return cuda_backend.cuda_unavailable_reason() or ""


gpu = pytest.mark.skipif(not torch.cuda.is_available(), reason=f"no CUDA GPU: {_no_cuda_reason()}")


def bgr(name: str) -> npt.NDArray[np.uint8]:
    return np.ascontiguousarray(getattr(data, name)()[:, :, ::-1])


@pytest.fixture(scope="module")
def onnx_detector(default_model: Path) -> Iterator[Detector]:
    with Detector.open(default_model, backend="onnx") as detector:
        yield detector


def _cuda_detector(path: Path, **options: Any) -> Detector:
    """Through the BACKENDS table once the ``cuda`` row is there, else the module directly."""
    if "cuda" in BACKENDS:
        return Detector.open(path, backend="cuda", **options)
    return Detector(cuda_backend.load(path, **options), path)


def _box_iou(a: npt.NDArray[np.float32], b: npt.NDArray[np.float32]) -> float:
    iw = max(0.0, float(min(a[2], b[2]) - max(a[0], b[0])))
    ih = max(0.0, float(min(a[3], b[3]) - max(a[1], b[1])))
    inter = iw * ih
    area = float((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]))
    return inter / (area - inter)


def assert_same_detections(want: DetectionResult, got: DetectionResult, tolerance: float) -> None:
    """Every confident detection of either has a same-class partner: IoU >= 0.9, close score."""
    assert (want.scores >= CONFIDENT).any(), "the reference found nothing confident to compare"
    for one, other in ((want, got), (got, want)):
        for i in np.flatnonzero(one.scores >= CONFIDENT):
            same = np.flatnonzero(other.class_ids == one.class_ids[i])
            assert same.size, f"{one.class_names[i]} ({one.scores[i]:.2f}) found by one side only"
            ious = [_box_iou(one.xyxy[i], other.xyxy[j]) for j in same]
            best = same[int(np.argmax(ious))]
            assert max(ious) >= MIN_IOU, f"{one.class_names[i]}: best IoU {max(ious):.3f}"
            assert abs(float(one.scores[i] - other.scores[best])) <= tolerance


def test_cpu_interpreter_matches_onnxruntime_on_the_default_model(
    default_model: Path, onnx_detector: Detector
) -> None:
    backend = cuda_backend.load(default_model, device="cpu", precision="fp32")
    batch, _ = onnx_detector.preprocess([bgr("chelsea")])
    batch = batch.copy()
    reference = OnnxBackend(default_model)
    want, got = reference.infer(batch)[0], backend.infer(batch)[0]
    assert got.shape == want.shape == (1, 25200, 85)
    np.testing.assert_allclose(got, want, rtol=1e-3, atol=2e-2)  # boxes: pixels up to 640
    detector = Detector(backend, default_model)
    assert_same_detections(
        onnx_detector.detect(bgr("chelsea")), detector.detect(bgr("chelsea")), 0.01
    )
    detector.close()


@gpu
@pytest.mark.gpu
@pytest.mark.parametrize(
    ("precision", "cuda_graphs"), [("fp16", True), ("fp16", False), ("fp32", True)]
)
@pytest.mark.parametrize("image", ["chelsea", "coffee"])
def test_gpu_detections_match_onnx_cpu(
    default_model: Path, onnx_detector: Detector, precision: str, cuda_graphs: bool, image: str
) -> None:
    with _cuda_detector(default_model, precision=precision, cuda_graphs=cuda_graphs) as detector:
        backend = detector.backend
        assert (backend.name, backend.device, backend.precision) == ("cuda", "cuda:0", precision)
        assert isinstance(backend, cuda_backend.CudaBackend)
        assert backend.cuda_graphs == cuda_graphs, backend.graph_error
        want = onnx_detector.detect(bgr(image))
        for _ in range(2):  # a replayed graph gives the same answer on its second run
            assert_same_detections(want, detector.detect(bgr(image)), SCORE_TOLERANCE[precision])


@gpu
@pytest.mark.gpu
def test_gpu_raw_outputs_match_onnxruntime(default_model: Path, onnx_detector: Detector) -> None:
    batch, _ = onnx_detector.preprocess([bgr("coffee")])
    batch = batch.copy()
    want = OnnxBackend(default_model).infer(batch)[0]
    fp32 = cuda_backend.load(default_model, precision="fp32", cuda_graphs=False)
    np.testing.assert_allclose(fp32.infer(batch)[0], want, rtol=1e-3, atol=5e-2)  # no TF32
    eager = cuda_backend.load(default_model, precision="fp16", cuda_graphs=False)
    graphed = cuda_backend.load(default_model, precision="fp16", cuda_graphs=True)
    eager_out, graph_out = eager.infer(batch)[0], graphed.infer(batch)[0]
    assert graph_out.dtype == np.float32
    np.testing.assert_allclose(graph_out, eager_out, rtol=1e-3, atol=1e-2)
    objectness = want[0, :, 4]
    confident = objectness > 0.25
    assert confident.any()
    np.testing.assert_allclose(graph_out[0, confident, 4], objectness[confident], atol=0.03)
    for backend in (fp32, eager, graphed):
        backend.close()


@gpu
@pytest.mark.gpu
def test_gpu_batches_replay_one_graph_per_size_and_match_single_images(
    default_model: Path, onnx_detector: Detector
) -> None:
    """Several cameras' frames in one batch: a CUDA graph per batch size (1, 2, 4, 5 here),
    one copy of the weights, and each image's outputs as a batch of one gives them."""
    photos = [bgr(name) for name in ("chelsea", "coffee", "astronaut", "rocket")]
    photos.append(np.ascontiguousarray(photos[0][::2, ::2]))  # the cat again, half the size
    rows = np.concatenate([onnx_detector.preprocess([p])[0].copy() for p in photos])
    backend = cuda_backend.CudaBackend(default_model, precision="fp16", max_batch=5)
    assert backend.batch_sizes == (1, 2, 4, 5) and backend.cuda_graphs, backend.graph_error
    singles = np.concatenate([backend.infer(rows[i : i + 1])[0] for i in range(5)])
    for n in (5, 3, 2):  # 3 runs on the graph of 4, padded
        # fp16, and cuDNN may pick other kernels per batch size: a pixel, 0.02 in score
        got = backend.infer(rows[:n])[0]
        np.testing.assert_allclose(got[..., :4], singles[:n, :, :4], rtol=1e-2, atol=1.0)
        np.testing.assert_allclose(got[..., 4:], singles[:n, :, 4:], atol=0.02)
    backend.close()
