"""The backend Protocol and the table of backends, with no backend imported.

Kept apart from the package's ``__init__`` so that :mod:`.select` (which ``open_backend`` calls
for ``auto``) and each runtime module can import these names without importing back the module
that imports them.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from common.contracts import BackendName
from common.errors import BackendUnavailable, ConfigError

Dim = int | None  # None: a dynamic dimension (named or unknown in the model)

#: Backend name -> module, imported only when that backend is asked for.
BACKENDS: dict[str, str] = {
    BackendName.ONNX: "services.detector.backends.onnx",
    BackendName.TENSORRT: "services.detector.backends.tensorrt",
    BackendName.CUDA: "services.detector.backends.cuda",
    BackendName.OPENVINO: "services.detector.backends.openvino",
}

#: The name that picks the best backend this machine can run (see :mod:`.select`).
AUTO = BackendName.AUTO

#: Every name ``--backend`` and ``detector.backend`` accept: the enum's members, in its order
#: (the default first, then by speed, then auto).
BACKEND_CHOICES: tuple[str, ...] = tuple(b.value for b in BackendName)


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


def import_backend(name: str) -> ModuleType:
    """Import the module of the backend called ``name``.

    Raises ConfigError for a name not in :data:`BACKENDS`, and BackendUnavailable when its
    runtime cannot be imported here (a module may also raise BackendUnavailable itself, with
    a better reason than the bare ImportError).
    """
    module_name = BACKENDS.get(name)
    if module_name is None:
        raise ConfigError(f"unknown backend {name!r}; valid backends: {', '.join(BACKEND_CHOICES)}")
    try:
        return importlib.import_module(module_name)
    except ImportError as exc:
        raise BackendUnavailable(f"backend {name!r} is unavailable on this machine: {exc}") from exc


def load_function(name: str) -> Callable[..., Backend]:
    """The ``load`` function of backend ``name`` (see :func:`import_backend` for errors)."""
    load: Callable[..., Backend] = import_backend(name).load
    return load


def supported_options(load: Callable[..., Backend]) -> frozenset[str] | None:
    """The keyword options ``load`` takes; None when it takes any (``**options``)."""
    params = list(inspect.signature(load).parameters.values())[1:]  # [0] is the model path
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    return frozenset(p.name for p in params)
