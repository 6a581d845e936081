"""What a loaded model is: input size, batch size, output family and class names.

Everything comes from the model itself (its declared shapes and Ultralytics-style metadata),
never from its file name. Dynamic dimensions are resolved in order: the declared shape, the
``imgsz`` metadata, then :data:`DEFAULT_INPUT_SIZE`; a dynamic output shape is resolved by one
probe inference on a blank batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.coco import COCO80
from common.errors import ModelError
from common.model_metadata import parse_names
from perception.decode import Family, OutputLayout, detect_family
from runtimes import Backend, Dim
from runtimes.base import input_size


@dataclass(frozen=True, slots=True)
class ModelInfo:
    """The facts the pipeline needs about a model.

    ``batch_size`` is the model's fixed batch, ``None`` when it takes any batch.
    """

    input_height: int
    input_width: int
    batch_size: int | None
    layout: OutputLayout
    names: tuple[str, ...]
    output_shape: tuple[Dim, ...]

    @property
    def family(self) -> Family:
        """The output family."""
        return self.layout.family


def _parse_bool(raw: str | None) -> bool | None:
    if raw is None:
        return None
    return {"true": True, "1": True, "false": False, "0": False}.get(raw.strip().lower())


def class_names(parsed: dict[int, str] | None, num_classes: int | None) -> tuple[str, ...]:
    """The model's class names: from metadata, else COCO-80 for 80 classes, else ``class_<i>``.

    ``num_classes`` is ``None`` when the output shape does not say (end-to-end models); the
    metadata then decides, and without it COCO-80 is assumed.
    """
    if num_classes is None:
        num_classes = max(parsed) + 1 if parsed else len(COCO80)
    if parsed is None:
        if num_classes == len(COCO80):
            return COCO80
        return tuple(f"class_{i}" for i in range(num_classes))
    return tuple(parsed.get(i, f"class_{i}") for i in range(num_classes))


def read_model_info(backend: Backend) -> ModelInfo:
    """Describe the model loaded in ``backend``.

    Raises ModelError for an input that is not ``[B, 3, H, W]`` and UnknownModelFamily for an
    output shape matching no family.
    """
    if not backend.output_shapes:
        raise ModelError("the model has no outputs")
    height, width = input_size(backend.input_shape, backend.metadata)
    batch = backend.input_shape[0]
    output_shape = backend.output_shapes[0]
    if len(output_shape) == 3 and None in output_shape[1:]:
        probe = np.zeros((batch or 1, 3, height, width), np.float32)
        output_shape = (batch, *backend.infer(probe)[0].shape[1:])
    names = parse_names(backend.metadata.get("names"))
    layout = detect_family(
        output_shape,
        num_names=len(names) if names is not None and max(names) + 1 == len(names) else None,
        input_hw=(height, width),
        end2end=_parse_bool(backend.metadata.get("end2end")),
    )
    return ModelInfo(
        input_height=height,
        input_width=width,
        batch_size=batch,
        layout=layout,
        names=class_names(names, layout.num_classes),
        output_shape=output_shape,
    )
