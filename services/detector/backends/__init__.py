"""Inference backends: one module per runtime, behind one Protocol, imported lazily.

A backend module exposes ``load(model_path, **options) -> Backend``. It imports its runtime at
module level, so importing the module is what fails on a machine without that runtime; the
table below is what lets CPU-only machines import the detector cleanly. To add a runtime
(``tensorrt``, ``cuda``), write its module and add one row: pre- and post-processing do not
change.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from common.errors import BackendUnavailable, ConfigError

Dim = int | None  # None: a dynamic dimension (named or unknown in the model)

#: Backend name -> module, imported only when that backend is asked for.
BACKENDS: dict[str, str] = {
    "onnx": "services.detector.backends.onnx",
}


@runtime_checkable
class Backend(Protocol):
    """A loaded model that runs one NCHW float32 batch at a time.

    ``input_shape`` and ``output_shapes`` are as the model declares them, ``None`` for
    dynamic dimensions; ``metadata`` is the model's string key/value metadata (Ultralytics
    puts ``names``, ``imgsz``, ``stride`` there).
    """

    @property
    def name(self) -> str:
        """The backend's name in :data:`BACKENDS`."""
        ...

    @property
    def device(self) -> str:
        """Where it runs, e.g. ``cpu`` or ``cuda:0``."""
        ...

    @property
    def precision(self) -> str:
        """Numeric precision of the model's input, e.g. ``fp32`` or ``fp16``."""
        ...

    @property
    def input_shape(self) -> tuple[Dim, ...]:
        """The declared input shape, ``[B, 3, H, W]``."""
        ...

    @property
    def output_shapes(self) -> tuple[tuple[Dim, ...], ...]:
        """The declared shape of each output, in output order."""
        ...

    @property
    def metadata(self) -> Mapping[str, str]:
        """The model's custom metadata."""
        ...

    def infer(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        """Run ``batch`` (``[B, 3, H, W]`` float32) and return every output as float32."""
        ...

    def close(self) -> None:
        """Release the runtime's resources; the backend is unusable afterwards."""
        ...


def open_backend(name: str, model_path: str | Path, **options: Any) -> Backend:
    """Load ``model_path`` with the backend called ``name``.

    Raises ConfigError for a name not in :data:`BACKENDS`, BackendUnavailable when its
    runtime cannot be imported here, and ModelError (from the backend) for a bad model file.
    """
    module_name = BACKENDS.get(name)
    if module_name is None:
        raise ConfigError(
            f"unknown backend {name!r}; valid backends: {', '.join(sorted(BACKENDS))}"
        )
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise BackendUnavailable(f"backend {name!r} is unavailable on this machine: {exc}") from exc
    load: Callable[..., Backend] = module.load
    return load(Path(model_path), **options)
