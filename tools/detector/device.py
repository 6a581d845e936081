"""``detect --device``, as the ``yolo`` command line takes it, turned into a backend and its
options: ``cpu``, ``0``, ``cuda`` or ``cuda:N``. Pure: nothing is loaded here."""

from __future__ import annotations

from typing import Any

from common.contracts import BackendName
from common.errors import ConfigError

_CPU_BACKENDS = (BackendName.ONNX, BackendName.OPENVINO, BackendName.AUTO)


def gpu_index(device: str) -> int | None:
    """The CUDA device index that ``device`` names, or None for ``cpu``."""
    text = device.strip().lower()
    if text == "cpu":
        return None
    if text == "cuda":
        return 0
    number = text.removeprefix("cuda:")
    if not number.isdigit():
        raise ConfigError(f"--device must be cpu, N, cuda or cuda:N, got {device!r}")
    return int(number)


def backend_for(backend: str | None, device: str | None) -> tuple[str, dict[str, Any]]:
    """The backend to open and its options. ``backend`` None means not given: ``onnx`` on the
    CPU, ``cuda`` (our interpreter on PyTorch) on a GPU."""
    if device is None:
        return backend or BackendName.ONNX, {}
    index = gpu_index(device)
    if index is None:
        if backend is None or backend in _CPU_BACKENDS:
            return backend or BackendName.ONNX, {}
        if backend == BackendName.CUDA:
            return backend, {"device": "cpu", "precision": "fp32"}
        raise ConfigError(f"--backend {backend} runs on a GPU only, not on --device cpu")
    if backend is None or backend == BackendName.CUDA:
        return BackendName.CUDA, {"device": f"cuda:{index}"}
    if backend == BackendName.TENSORRT:
        return backend, {"device": index}
    raise ConfigError(
        f"--backend {backend} runs on the CPU only; for --device {device} use cuda or tensorrt"
    )
