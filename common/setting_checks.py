"""The checks every settings dataclass shares, each raising ConfigError with one line.

Every number a setting holds is bounded by a range a real robot could want, declared once per
dataclass in a ``BOUNDS`` table (``{"rate_hz": (0.1, 1000)}``) that ``check_bounds`` walks at
start-up; a list setting's length is bounded the same way by ``LENGTHS``. A value outside
(NaN and inf included) stops the service with one line that names the setting, the value and
the range: ``controller.max_linear must be within 0.01..5 m/s, got 1000.0``. A unit test
checks that every numeric and list field of every table is in one of the two.
"""

from __future__ import annotations

from collections.abc import Mapping, Sized
from enum import StrEnum

from common.errors import ConfigError

#: ``field name -> (lowest, highest)``, both allowed. For a tuple of numbers, each item.
Bounds = Mapping[str, tuple[float, float]]

# The unit a field's name ends in, said in the message so that the range reads unambiguously.
_UNITS = (("_hz", " Hz"), ("_s", " s"), ("_m", " m"), ("_deg", " deg"))
_EXTRA_UNITS = {
    "max_linear": " m/s",
    "forward_speed": " m/s",
    "max_angular": " rad/s",
    "max_linear_accel": " m/s^2",
    "max_angular_accel": " rad/s^2",
}


def _number(x: float) -> str:
    """A bound as people write it: 5, not 5.0; 0.01, not 1e-02."""
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def _unit(name: str) -> str:
    field = name.rsplit(".", 1)[-1]
    if field in _EXTRA_UNITS:
        return _EXTRA_UNITS[field]
    return next((unit for suffix, unit in _UNITS if field.endswith(suffix)), "")


def range_text(name: str, lo: float, hi: float) -> str:
    """How a setting's range reads in its error and in docs/configuration.md: ``0.01..5 m/s``."""
    return f"{_number(lo)}..{_number(hi)}{_unit(name)}"


def within(name: str, value: float, lo: float, hi: float) -> None:
    """``value`` must be a number in ``lo..hi`` (NaN never is)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not lo <= value <= hi:
        raise ConfigError(f"{name} must be within {range_text(name, lo, hi)}, got {value!r}")


def check_bounds(settings: object, table: str, bounds: Bounds) -> None:
    """Check every field named in ``bounds`` (each item of a tuple field)."""
    for field, (lo, hi) in bounds.items():
        value = getattr(settings, field)
        name = f"{table}.{field}"
        if isinstance(value, tuple):
            for item in value:
                if (
                    isinstance(item, bool)
                    or not isinstance(item, int | float)
                    or not (lo <= item <= hi)
                ):
                    raise ConfigError(
                        f"{name} must be numbers within {_number(lo)}..{_number(hi)}, "
                        f"got {list(value)}"
                    )
        else:
            within(name, value, lo, hi)


def check_lengths(settings: object, table: str, lengths: Bounds) -> None:
    """Check the number of items of every list field named in ``lengths``."""
    for field, (lo, hi) in lengths.items():
        value: Sized = getattr(settings, field)
        if not lo <= len(value) <= hi:
            what = f"{_number(lo)}..{_number(hi)} items" if hi > lo else f"{_number(lo)} items"
            shown = list(value) if len(value) <= 8 else f"{len(value)} items"  # type: ignore[call-overload]
            raise ConfigError(f"{table}.{field} must have {what}, got {shown}")


def enum_field(settings: object, name: str, kind: type[StrEnum], where: str) -> None:
    """Turn a plain string field into its enum member (settings built in code pass strings)."""
    value = getattr(settings, name)
    try:
        object.__setattr__(settings, name, kind(value))
    except ValueError:
        choices = ", ".join(m.value for m in kind)
        raise ConfigError(f"{where} must be one of {choices}, got {value!r}") from None
