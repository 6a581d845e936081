"""The CUDA runtime's bindings (cuda-python), as the GPU probes and TensorRT use them."""

from __future__ import annotations

import importlib
from types import ModuleType


def import_cudart() -> ModuleType:
    """The CUDA runtime bindings of ``cuda-python``, whichever layout is installed.

    cuda-python 12.6 and later put them at ``cuda.bindings.runtime``; older releases at
    ``cuda.cudart``. Raises ImportError when neither is there.
    """
    try:
        return importlib.import_module("cuda.bindings.runtime")
    except ImportError:
        return importlib.import_module("cuda.cudart")


def cuda_device_count(cudart: ModuleType) -> tuple[int, str]:
    """``(number of CUDA devices, "" or the error)`` as the CUDA runtime sees them."""
    err, count = cudart.cudaGetDeviceCount()
    if err != cudart.cudaError_t.cudaSuccess:
        _, text = cudart.cudaGetErrorString(err)
        return 0, text.decode() if isinstance(text, bytes) else str(text)
    return int(count), ""
