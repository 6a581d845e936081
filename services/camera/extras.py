"""Optional extras, imported only when a source names them, each failing with one line."""

from __future__ import annotations

import importlib
from types import ModuleType

from common.errors import ConfigError


def import_extra(module: str, extra: str, spec: str) -> ModuleType:
    """``module``, or ConfigError with one line saying how to install it (``pip install
    '.[extra]'``) or why it did not load (a missing system library such as libusb)."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name != module:  # the package is there, something it imports is not
            raise ConfigError(f"{spec}: {module} cannot load ({exc})") from exc
        raise ConfigError(
            f"{spec}: {module} is not installed; install the {extra} extra: "
            f"pip install '.[{extra}]'"
        ) from exc
    except ImportError as exc:  # e.g. "libusb-1.0.so.0: cannot open shared object file"
        raise ConfigError(f"{spec}: {module} cannot load ({exc})") from exc
