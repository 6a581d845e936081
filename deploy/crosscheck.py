"""Settings of different services that cannot work together, refused before anything starts.

Each service checks its own settings when it starts; only the supervisor sees the whole stack,
so only it can tell that the detector's class filter hides what the controller looks for, or
that the controller looks for a class the model never reports: a stack that would run and
never move the robot. Each is one ConfigError line (exit 2), with a likely fix.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from pathlib import Path

from common.coco import COCO80
from common.errors import ConfigError
from common.model_metadata import parse_names
from stack.config import Config

#: Reads the class names of the model the detector will load (None: unknown before it loads).
ClassReader = Callable[[Config], tuple[str, ...] | None]


def cross_check(config: Config, model_classes: ClassReader) -> None:
    """Refuse a detector and a controller that cannot work together (both must be services of
    this supervisor: a detector on another host is checked by its controller at run time)."""
    services = config.supervisor.services
    if "detector" not in services or "controller" not in services:
        return
    targets = config.controller.target_classes
    kept = config.detector.classes
    if kept:
        hidden = [t for t in targets if t not in kept]
        if hidden:
            raise ConfigError(
                f"detector.classes {list(kept)} filters out controller.target_classes "
                f"{hidden}: the controller would never see its target; add them to "
                "detector.classes (or leave it empty for every class)"
            )
    classes = model_classes(config)
    if classes is None:
        return
    unknown = [t for t in targets if t not in classes]
    if unknown:
        hints = [f"{t!r} -> {close[0]!r}" for t in unknown if (close := _closest(t, classes))]
        hint = f" (did you mean {', '.join(hints)}?)" if hints else ""
        raise ConfigError(
            f"controller.target_classes {unknown} are not among the model's {len(classes)} "
            f"classes{hint}: the robot would never see them"
        )


def _closest(name: str, classes: tuple[str, ...]) -> list[str]:
    return difflib.get_close_matches(name, classes, n=1, cutoff=0.6)


def model_classes(config: Config) -> tuple[str, ...] | None:
    """The class names of the detector's model: COCO's 80 for the default model, the
    ``names`` metadata of another ONNX file, None when that cannot be read here (another
    format, a file that is missing: the detector says so itself when it starts)."""

    if not config.detector.model:
        return COCO80
    path = Path(config.detector.model)
    if path.suffix != ".onnx" or not path.is_file():
        return None
    import onnx
    from google.protobuf.message import DecodeError  # type: ignore[import-untyped]

    try:
        model = onnx.load(str(path), load_external_data=False)
    except (OSError, ValueError, DecodeError):
        return None
    names = parse_names({p.key: p.value for p in model.metadata_props}.get("names"))
    if not names:
        return None
    return tuple(names[i] for i in sorted(names))
