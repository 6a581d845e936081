"""The backend Protocol, its names and the input-shape helpers: what every runtime module
imports. The table of runtime modules is :mod:`.table`, which no runtime imports (no cycle).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from common.contracts import BackendName
from common.errors import ConfigError, ModelError
from common.model_metadata import literal

Dim = int | None  # None: a dynamic dimension (named or unknown in the model)

#: The name that picks the best backend this machine can run (see :mod:`.select`).
AUTO = BackendName.AUTO

#: Every name ``--backend`` and ``detector.backend`` accept: the enum's members, in its order
#: (the default first, then by speed, then auto).
BACKEND_CHOICES: tuple[str, ...] = tuple(b.value for b in BackendName)


def check_cpu_backend_args(model_path: Path, threads: int | None, max_batch: int) -> None:
    """What a CPU backend checks before it loads ``model_path``: a thread count and a
    batch size of at least one (ConfigError), and a model file that is there (ModelError)."""
    if threads is not None and threads < 1:
        raise ConfigError(f"threads must be a positive integer, got {threads}")
    if max_batch < 1:
        raise ConfigError(f"max_batch must be a positive integer, got {max_batch}")
    if not model_path.is_file():
        raise ModelError(f"{model_path}: no such model file")


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


#: Square input size used when neither the shape nor the metadata fixes it.
DEFAULT_INPUT_SIZE = 640


def parse_imgsz(raw: str | None) -> tuple[int, int] | None:
    """Parse ``imgsz`` metadata (``"640"`` or ``"[384, 640]"``) into ``(height, width)``."""
    value = literal(raw)
    if isinstance(value, int) and value > 0:
        return value, value
    if (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, int) and v > 0 for v in value)
    ):
        return int(value[0]), int(value[1])
    return None


def input_size(input_shape: Sequence[Dim], metadata: Mapping[str, str]) -> tuple[int, int]:
    """``(height, width)`` of the network input; ``[B, 3, H, W]`` is checked.

    A dynamic H or W falls back to the ``imgsz`` metadata, then to 640.
    """
    if len(input_shape) != 4 or input_shape[1] not in (3, None):
        shown = ["?" if d is None else d for d in input_shape]
        raise ModelError(f"model input shape {shown} is not [B, 3, H, W] (NCHW, 3 channels)")
    meta_hw = parse_imgsz(metadata.get("imgsz"))
    fallback = meta_hw or (DEFAULT_INPUT_SIZE, DEFAULT_INPUT_SIZE)
    height = input_shape[2] if input_shape[2] is not None else fallback[0]
    width = input_shape[3] if input_shape[3] is not None else fallback[1]
    return height, width
