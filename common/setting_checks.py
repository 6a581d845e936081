"""The checks every settings dataclass shares, each raising ConfigError with one line.

Every number a setting holds is bounded by a range a real robot could want, declared once, on
its field: ``rate_hz: Annotated[float, Range(0.1, 1000)] = 10.0`` (for a tuple of numbers, each
item); a list setting's length the same way, ``Annotated[tuple[str, ...], Length(0, 16)]``.
``check_bounds`` and ``check_lengths`` walk those declarations at start-up (common/fields.py
bounds a wire message's ints the same way, with the same ``Range``, common/field_types.py's).
A value outside (NaN and inf included) stops the service with one line that names the setting,
the value and the range: ``controller.max_linear must be within 0.01..5 m/s, got 1000.0``. A
unit test checks that every numeric and list field of every table declares one.
"""

from __future__ import annotations

import functools
import inspect
import typing
from collections.abc import Mapping, Sized
from dataclasses import dataclass
from enum import StrEnum

from common.errors import ConfigError
from common.field_types import Range

__all__ = [
    "Bounds",
    "Length",
    "Range",
    "check_bounds",
    "check_lengths",
    "declared_bounds",
    "declared_lengths",
    "enum_field",
    "range_text",
    "within",
]

#: ``field name -> (lowest, highest)``, both allowed. For a tuple of numbers, each item.
Bounds = Mapping[str, tuple[float, float]]


@dataclass(frozen=True, slots=True)
class Length:
    """How many items a list setting may hold, both allowed:
    ``Annotated[tuple[str, ...], Length(0, 16)]``."""

    lo: int
    hi: int


def _declared(cls: type, kind: type[Range | Length], own: bool) -> dict[str, tuple[float, float]]:
    """``{field: (lo, hi)}`` of each field of ``cls`` annotated with a ``kind`` (Range or
    Length), in the order the fields are declared; ``own``: only those ``cls`` itself declares,
    not those it inherits."""
    hints = typing.get_type_hints(cls, include_extras=True)
    names = inspect.get_annotations(cls) if own else hints
    out: dict[str, tuple[float, float]] = {}
    for name in names:
        marks = [m for m in getattr(hints[name], "__metadata__", ()) if isinstance(m, kind)]
        if not marks:
            continue
        lo, hi = marks[0].lo, marks[0].hi
        if lo is None or hi is None:
            raise TypeError(f"{cls.__name__}.{name}: a setting's {kind.__name__} needs both bounds")
        out[name] = (lo, hi)
    return out


@functools.cache
def _own(cls: type, kind: type[Range | Length]) -> Bounds:
    return _declared(cls, kind, own=True)


def declared_bounds(cls: type) -> dict[str, tuple[float, float]]:
    """Each bounded numeric field of the settings dataclass ``cls`` (inherited ones included),
    ``{field: (lo, hi)}``: what docs/configuration.md lists and the tests walk."""
    return _declared(cls, Range, own=False)


def declared_lengths(cls: type) -> dict[str, tuple[float, float]]:
    """Each list field's bounded length, ``{field: (lo, hi)}``, as :func:`declared_bounds`."""
    return _declared(cls, Length, own=False)


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


def check_bounds(settings: object, table: str, declared_in: type) -> None:
    """Check every field that ``declared_in`` (the dataclass of ``settings`` or a base of it)
    declares with a Range (each item of a tuple field)."""
    for field, (lo, hi) in _own(declared_in, Range).items():
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


def check_lengths(settings: object, table: str, declared_in: type) -> None:
    """Check the number of items of every list field that ``declared_in`` declares with a
    Length."""
    for field, (lo, hi) in _own(declared_in, Length).items():
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
