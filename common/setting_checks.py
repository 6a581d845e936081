"""The checks every settings dataclass shares, each raising ConfigError with one line."""

from __future__ import annotations

import math
from enum import StrEnum

from common.errors import ConfigError


def positive(name: str, value: float) -> None:
    if not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{name} must be a positive number, got {value}")


def non_negative(name: str, value: float) -> None:
    if not (value >= 0 and math.isfinite(value)):
        raise ConfigError(f"{name} must be a finite number >= 0, got {value}")


def fraction(name: str, value: float) -> None:
    if not 0 <= value <= 1:
        raise ConfigError(f"{name} must be within 0..1, got {value}")


def enum_field(settings: object, name: str, kind: type[StrEnum], where: str) -> None:
    """Turn a plain string field into its enum member (settings built in code pass strings)."""
    value = getattr(settings, name)
    try:
        object.__setattr__(settings, name, kind(value))
    except ValueError:
        choices = ", ".join(m.value for m in kind)
        raise ConfigError(f"{where} must be one of {choices}, got {value!r}") from None
