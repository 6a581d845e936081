"""Inference backends: one module per runtime, behind one Protocol, imported lazily.

A backend module exposes ``load(model_path, **options) -> Backend``. It imports its runtime at
module level, so importing the module is what fails on a machine without that runtime; the
table in :mod:`.base` is what lets CPU-only machines import the detector cleanly. To add a runtime,
write its module and add one row: pre- and post-processing do not change.

``auto`` is not a row: :func:`open_backend` hands it to :mod:`.select`, which probes the rows
in order of speed (tensorrt, cuda, openvino on CPUs with VNNI or AMX, onnx) and loads the first
that works here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from common.errors import ConfigError
from runtimes.base import AUTO, BACKEND_CHOICES, Backend, Dim
from runtimes.select import open_auto
from runtimes.table import BACKENDS, import_backend, load_function, supported_options

__all__ = [
    "AUTO",
    "BACKENDS",
    "BACKEND_CHOICES",
    "Backend",
    "Dim",
    "import_backend",
    "load_function",
    "open_backend",
    "supported_options",
]


def open_backend(name: str, model_path: str | Path, **options: Any) -> Backend:
    """Load ``model_path`` with the backend called ``name``, or the best one for ``auto``.

    Raises ConfigError for an unknown name or an option that backend does not take,
    BackendUnavailable when its runtime cannot be imported here, and ModelError (from the
    backend) for a bad model file. ``auto`` drops options its choice does not take.
    """
    if name == AUTO:
        return open_auto(Path(model_path), options)
    load = load_function(name)
    taken = supported_options(load)
    unknown = sorted(set(options) - taken) if taken is not None else []
    if unknown:
        raise ConfigError(
            f"backend {name!r} takes no option(s) {', '.join(unknown)}; "
            f"it takes: {', '.join(sorted(taken or ())) or 'none'}"
        )
    return load(Path(model_path), **options)
