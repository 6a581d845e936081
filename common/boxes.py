"""The detections of one image as one struct of arrays, validated in one place.

Row ``i`` of every array describes detection ``i`` (supervision's layout): ``xyxy`` (n, 4)
float32 corners x1, y1, x2, y2 in pixels, origin top-left; ``scores`` (n,) float32;
``class_ids`` (n,) int32; ``track_ids`` (n,) int32 (-1: no track) or None when nothing tracked
them; ``columns``, named per-detection arrays that a feature adds beside these (a distance, a
mask id: supervision's ``Detections.data``), each (n,) of a ``COLUMN_DTYPES`` type, NaN where a
float value is unknown. Which image the pixels belong to is the producer's to say: the network
input for decoded candidates, the original image after post-processing and in messages.

The decoder's candidates, post-processing, the detector's result, the tracker's input, the
Detections message, the evaluator and the recording comparison all carry :class:`Boxes`;
:func:`check_boxes` is the one function that validates such arrays, and :func:`valid_rows` the
one definition of a box that may be kept.

The field annotations are also the wire layout (common/fields.py): a Detections message carries
its Boxes inline, each array as a key of the message body beside the row count ``n``, which a
decoder bounds by ``MAX_DETECTIONS`` before reading any array; ``columns`` travels as one
map, name -> dtype and bytes, read by every converter generically (docs/messages.md).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Annotated, Any

import numpy as np
import numpy.typing as npt

from common.field_types import COLUMN_DTYPES, Columns, Dim, Shape
from common.limits import MAX_COLUMN_NAME_CHARS, MAX_COLUMNS
from common.limits import MAX_DETECTIONS as MAX_DETECTIONS

N_DETECTIONS = Dim("n", 0, MAX_DETECTIONS)
#: A column's name: a letter, then letters, digits and underscores (``distance_m``), so that
#: it is a plain key in JSON, a plot path in Foxglove and a word in a label.
COLUMN_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_COLUMN_TYPES = frozenset(np.dtype(name) for name in COLUMN_DTYPES)


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"shape {value.shape} dtype {value.dtype}"
    return f"a {type(value).__name__}"


def _check_column(name: str, value: Any, n: int, dtype: type[np.generic]) -> None:
    if not (isinstance(value, np.ndarray) and value.shape == (n,) and value.dtype == dtype):
        kind = np.dtype(dtype).name
        raise ValueError(
            f"{name} must be a ({n},) {kind} array to match xyxy, got {_describe(value)}"
        )


def valid_rows(
    xyxy: npt.NDArray[np.float32], scores: npt.NDArray[np.float32]
) -> npt.NDArray[np.bool_]:
    """(n,) mask of the rows that are boxes: finite corners and score, x2 >= x1, y2 >= y1."""
    return (
        np.isfinite(xyxy).all(axis=1)
        & np.isfinite(scores)
        & (xyxy[:, 2] >= xyxy[:, 0])
        & (xyxy[:, 3] >= xyxy[:, 1])
    )


def check_boxes(xyxy: Any, scores: Any, class_ids: Any, track_ids: Any = None) -> None:
    """Raise ValueError, saying what was expected, unless the arrays are valid detections.

    Expected: ``xyxy`` an (n, 4) float32 array, ``scores`` (n,) float32, ``class_ids`` (n,)
    int32, ``track_ids`` None or (n,) int32; every corner and score finite; x2 >= x1 and
    y2 >= y1. The first problem found is reported, with the offending row where there is one.
    """
    if not (
        isinstance(xyxy, np.ndarray)
        and xyxy.ndim == 2
        and xyxy.shape[1] == 4
        and xyxy.dtype == np.float32
    ):
        raise ValueError(f"xyxy must be an (n, 4) float32 array, got {_describe(xyxy)}")
    n = xyxy.shape[0]
    _check_column("scores", scores, n, np.float32)
    _check_column("class_ids", class_ids, n, np.int32)
    if track_ids is not None:
        _check_column("track_ids", track_ids, n, np.int32)
    ok = valid_rows(xyxy, scores)
    if ok.all():
        return
    row = int(np.flatnonzero(~ok)[0])
    box, score = xyxy[row].tolist(), float(scores[row])
    if not (np.isfinite(xyxy[row]).all() and np.isfinite(score)):
        raise ValueError(
            f"boxes and scores must be finite, got box {box} score {score} in row {row}"
        )
    raise ValueError(f"boxes must have x2 >= x1 and y2 >= y1, got {box} in row {row}")


def check_columns(columns: Any, n: int) -> None:
    """Raise ValueError, saying what was expected, unless ``columns`` is a mapping of at most
    MAX_COLUMNS names (COLUMN_NAME, at most MAX_COLUMN_NAME_CHARS) to (n,) arrays of a
    COLUMN_DTYPES type in native byte order."""
    if not isinstance(columns, Mapping):
        raise ValueError(f"columns must be a mapping of names to arrays, got {_describe(columns)}")
    if len(columns) > MAX_COLUMNS:
        raise ValueError(f"{len(columns)} columns is over the limit of {MAX_COLUMNS}")
    for name, values in columns.items():
        if not (
            isinstance(name, str)
            and len(name) <= MAX_COLUMN_NAME_CHARS
            and COLUMN_NAME.fullmatch(name)
        ):
            raise ValueError(
                f"a column name must match {COLUMN_NAME.pattern} in at most "
                f"{MAX_COLUMN_NAME_CHARS} characters, got {name!r}"
            )
        if not (
            isinstance(values, np.ndarray)
            and values.shape == (n,)
            and values.dtype in _COLUMN_TYPES
        ):
            raise ValueError(
                f"column {name!r} must be an ({n},) array of {', '.join(COLUMN_DTYPES)} to "
                f"match xyxy, got {_describe(values)}"
            )


_NO_COLUMNS: Mapping[str, npt.NDArray[Any]] = MappingProxyType({})


def _no_columns() -> Mapping[str, npt.NDArray[Any]]:
    return _NO_COLUMNS


def _empty_xyxy() -> npt.NDArray[np.float32]:
    return np.zeros((0, 4), np.float32)


def _empty_scores() -> npt.NDArray[np.float32]:
    return np.zeros(0, np.float32)


def _empty_ids() -> npt.NDArray[np.int32]:
    return np.zeros(0, np.int32)


@dataclass(frozen=True, slots=True, kw_only=True)
class Boxes:
    """Detections as a struct of arrays (see the module docstring); empty by default.

    Checked by :func:`check_boxes` and :func:`check_columns` on construction, so a Boxes never
    holds a NaN box, an inverted box or a row count that disagrees between arrays. ``columns``
    is kept as a read-only copy of the mapping given; every operation that selects rows selects
    the columns' rows too.
    """

    xyxy: Annotated[npt.NDArray[np.float32], Shape(N_DETECTIONS, 4)] = dataclasses.field(
        default_factory=_empty_xyxy
    )
    scores: Annotated[npt.NDArray[np.float32], Shape(N_DETECTIONS)] = dataclasses.field(
        default_factory=_empty_scores
    )
    class_ids: Annotated[npt.NDArray[np.int32], Shape(N_DETECTIONS)] = dataclasses.field(
        default_factory=_empty_ids
    )
    track_ids: Annotated[npt.NDArray[np.int32], Shape(N_DETECTIONS)] | None = None
    columns: Annotated[
        Mapping[str, npt.NDArray[Any]],
        Columns(N_DETECTIONS, MAX_COLUMNS, MAX_COLUMN_NAME_CHARS),
    ] = dataclasses.field(default_factory=_no_columns)

    def __post_init__(self) -> None:
        check_boxes(self.xyxy, self.scores, self.class_ids, self.track_ids)
        columns = self.columns
        if columns is _NO_COLUMNS:
            return
        if type(columns) is dict and not columns:  # the decoder's, for most messages
            object.__setattr__(self, "columns", _NO_COLUMNS)
            return
        check_columns(columns, len(self))
        # A copy behind a read-only view: the caller's dict may change, this may not.
        frozen = MappingProxyType(dict(columns)) if columns else _NO_COLUMNS
        object.__setattr__(self, "columns", frozen)

    def __len__(self) -> int:
        return int(self.xyxy.shape[0])

    def take(self, index: npt.NDArray[np.intp]) -> Boxes:
        """The rows at ``index`` (integer indices, in that order), track ids and columns
        included."""
        return Boxes(
            xyxy=self.xyxy[index],
            scores=self.scores[index],
            class_ids=self.class_ids[index],
            track_ids=None if self.track_ids is None else self.track_ids[index],
            columns={name: values[index] for name, values in self.columns.items()},
        )

    def with_xyxy(self, xyxy: npt.NDArray[np.float32]) -> Boxes:
        """The same detections with their corners moved (e.g. into another image's pixels)."""
        return dataclasses.replace(self, xyxy=xyxy)

    def with_track_ids(self, track_ids: npt.NDArray[np.int32] | None) -> Boxes:
        """The same detections with these track ids (None: untracked)."""
        return dataclasses.replace(self, track_ids=track_ids)

    def with_columns(self, columns: Mapping[str, npt.NDArray[Any]]) -> Boxes:
        """The same detections with ``columns`` added (one of the same name replaced)."""
        return dataclasses.replace(self, columns={**self.columns, **columns})
