"""The marks a message's or a setting's type hint carries (``Annotated[int, Range(lo=0)]``,
``Annotated[npt.NDArray[np.float32], Shape(N, 4)]`` ...): what common/fields.py's field walk
reads to know how a field travels and what a decoder accepts (its module docstring says each
mark's rule), and what common/setting_checks.py reads to bound a setting. Plain data: no
import of numpy, no codec."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated


@dataclass(frozen=True, slots=True)
class Range:
    """Bounds of a number, both allowed: an int field of a message, checked on decode
    (``Annotated[int, Range(lo=0)]``); a setting, checked when its dataclass is made
    (``Annotated[float, Range(0.1, 1000)]``, both bounds: common/setting_checks.py)."""

    lo: float | None = None
    hi: float | None = None


@dataclass(frozen=True, slots=True)
class Dim:
    """A count that sizes arrays; it travels as its own key ``name`` (e.g. "n")."""

    name: str
    lo: int
    hi: int


@dataclass(frozen=True, slots=True)
class Shape:
    """An array field's shape: ints, Dims or one -1 (from the byte length)."""

    dims: tuple[int | Dim, ...]

    def __init__(self, *dims: int | Dim) -> None:
        object.__setattr__(self, "dims", dims)


#: The element types a column may have: what every msgpack reader can take as raw bytes and
#: read back exactly (bool as one byte, 0 or 1). The numpy names travel on the wire.
COLUMN_DTYPES = ("bool", "int32", "int64", "float32", "float64")


@dataclass(frozen=True, slots=True)
class Columns:
    """A field of named per-row arrays, each (rows,) of a COLUMN_DTYPES type (module docstring).

    ``max_columns`` and ``max_name_chars`` bound what a decoder reads; the owner's
    ``__post_init__`` checks the rest (the names' form, the dtypes of arrays built in memory).
    """

    rows: Dim
    max_columns: int
    max_name_chars: int


@dataclass(frozen=True, slots=True)
class Inline:
    """A dataclass field whose own fields travel as keys of its parent's body, not as a map of
    their own: ``boxes: Annotated[Boxes, Inline()]``."""


NonNegativeInt = Annotated[int, Range(lo=0)]
