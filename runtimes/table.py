"""The table of backends: a name -> the runtime module that implements it, imported lazily.

No runtime module imports this one, so the table may name them all without a cycle.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from types import ModuleType

from common.contracts import BackendName
from common.errors import BackendUnavailable, ConfigError
from runtimes.base import BACKEND_CHOICES, Backend

#: Backend name -> module, imported only when that backend is asked for.
BACKENDS: dict[str, str] = {
    BackendName.ONNX: "runtimes.onnx",
    BackendName.TENSORRT: "runtimes.tensorrt",
    BackendName.CUDA: "runtimes.cuda",
    BackendName.OPENVINO: "runtimes.openvino",
}


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
