"""Batched inference on the real default model: a batch gives each image what a batch of one
gives it, on every backend this machine runs (onnx, openvino when installed, and the cuda
backend's interpreter on CPU PyTorch; the GPUs' own runs are in test_cuda_backend.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from common.errors import BackendUnavailable
from common.images import load_sample
from perception.pipeline import Detector
from runtimes import Backend, open_backend

pytestmark = pytest.mark.integration

PHOTOS = ("astronaut", "chelsea", "coffee")
TOLERANCE = 1e-4  # the outputs of a batch against those of single images (relative and absolute)


@pytest.fixture(scope="module")
def photos() -> list[npt.NDArray[np.uint8]]:
    return [load_sample(name) for name in PHOTOS]


@pytest.fixture(scope="module")
def reference(default_model: Path) -> Iterator[Detector]:
    with Detector.open(default_model, backend="onnx") as det:  # max_batch 1: batch pinned to 1
        assert det.info.batch_size == 1
        yield det


def _backends(default_model: Path, n: int) -> Iterator[tuple[str, Backend]]:
    """Each CPU backend opened for batches of up to ``n``; the missing optional ones said."""
    yield "onnx", open_backend("onnx", default_model, max_batch=n)
    try:
        yield "openvino", open_backend("openvino", default_model, max_batch=n)
    except BackendUnavailable as exc:  # the optional extra
        print(f"openvino left out: {exc}")
    try:
        from runtimes import cuda
    except ImportError as exc:
        print(f"the cuda backend's interpreter left out: {exc}")
        return
    yield "cuda (CPU)", cuda.load(default_model, device="cpu", precision="fp32", max_batch=n)


def test_a_batch_of_three_equals_three_batches_of_one(
    default_model: Path, reference: Detector, photos: list[npt.NDArray[np.uint8]]
) -> None:
    rows = np.concatenate([reference.preprocess([p])[0].copy() for p in photos])
    want = np.concatenate([reference.backend.infer(rows[i : i + 1])[0] for i in range(3)])
    for name, backend in _backends(default_model, len(photos)):
        try:
            assert backend.input_shape[0] is None, name  # takes a batch
            got = backend.infer(rows)[0]
            assert got.shape == want.shape, name
            np.testing.assert_allclose(got, want, rtol=TOLERANCE, atol=TOLERANCE, err_msg=name)
            # and a smaller batch than the largest runs as well
            np.testing.assert_allclose(
                backend.infer(rows[:2])[0], want[:2], rtol=TOLERANCE, atol=TOLERANCE, err_msg=name
            )
        finally:
            backend.close()


def test_detect_batch_equals_one_detect_per_image(
    default_model: Path, reference: Detector, photos: list[npt.NDArray[np.uint8]]
) -> None:
    with Detector.open(default_model, backend="onnx", max_batch=3) as batched:
        assert batched.info.batch_size is None
        results = batched.detect_batch(photos)
    for photo, got in zip(photos, results, strict=True):
        want = reference.detect(photo)
        assert len(want) > 0 and got.class_names == want.class_names
        np.testing.assert_allclose(got.boxes.xyxy, want.boxes.xyxy, atol=1e-2)
        np.testing.assert_allclose(got.boxes.scores, want.boxes.scores, atol=TOLERANCE)
