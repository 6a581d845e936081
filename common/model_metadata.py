"""Ultralytics-style ONNX metadata values (``names``, ``imgsz`` ...), parsed without loading
anything: the detector reads them from a loaded model, the supervisor from the file to check
settings against the model's classes before anything starts."""

from __future__ import annotations

import ast


def literal(raw: str | None) -> object:
    """A metadata value as a Python literal, or None when absent or not a literal."""
    if not raw:
        return None
    try:
        return ast.literal_eval(raw)
    except (ValueError, SyntaxError, MemoryError, RecursionError):
        return None


def parse_names(raw: str | None) -> dict[int, str] | None:
    """Parse Ultralytics' ``names`` metadata (``"{0: 'person', ...}"`` or a list literal).

    Returns ``None`` when absent or not a dict/list of names.
    """
    value = literal(raw)
    if isinstance(value, (list, tuple)):
        value = dict(enumerate(value))
    if not isinstance(value, dict) or not value:
        return None
    if not all(isinstance(k, int) and k >= 0 and isinstance(v, str) for k, v in value.items()):
        return None
    return {int(k): str(v) for k, v in value.items()}


#: Where an OpenVINO IR keeps the ONNX model's metadata (class names, imgsz) in its rt_info.
OPENVINO_METADATA_KEY = "detector_metadata"
