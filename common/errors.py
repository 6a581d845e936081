"""The one exception tree of the stack.

    StackError                   base of everything we raise on purpose
    ├── ConfigError              bad settings or stack config: exit non-zero with one line
    │   ├── DatasetError         a labelled dataset that cannot be evaluated
    │   │                        (tools/evaluation/labelled.py)
    │   └── NotPrepared          a model file serving needs that `zstack prepare` has not
    │                            made yet (perception/variants.py)
    ├── DecodeError              bytes on a Zenoh key that are not a valid message
    │   ├── ConflictError        an announcement that contradicts the one believed of its name
    │   │                        (common/announce.py)
    │   └── FieldMismatch        a value that does not fit its message field, inside the field
    │                            walk, which raises a DecodeError naming the field's path
    │                            (common/field_codecs.py)
    ├── ImageError               a missing, unreadable or corrupt image
    │   └── ImageTooLarge        an image over the pixel budget, refused before decoding
    ├── ModelError               a file that is not a usable model
    │   ├── UnknownModelFamily   an output shape that matches no known YOLO family
    │   ├── ModelFetchError      the default model could not be fetched or converted
    │   └── QuantizationFailed   no working INT8 model could be made: stay on FP32
    │                            (modelprep/quantize)
    ├── BackendUnavailable       a runtime (TensorRT, CUDA, ...) that this machine lacks
    └── RecordingError           a file that is not a readable MCAP recording, or holds nothing
                                 that can be played

Every subclass of StackError in the project is drawn here, under its base
(tests/unit/common/test_errors.py checks it); the ones defined outside this module name it.

Library errors are translated at the boundary (``raise ModelError(...) from exc``) so callers
only ever catch these. Command-line entry points print ``str(error)`` as one line and exit
non-zero; they never show a traceback for a StackError.
"""

from __future__ import annotations


class StackError(Exception):
    """Base class of every error the stack raises on purpose."""


class ConfigError(StackError):
    """Invalid settings or stack configuration."""


class DecodeError(StackError):
    """A payload that does not decode to the expected message."""


class ImageError(StackError):
    """An image that is missing, unreadable or corrupt."""


class ImageTooLarge(ImageError):
    """An image whose header claims more pixels than the budget allows (never decoded)."""


class ModelError(StackError):
    """A file that is not a usable detection model."""


class UnknownModelFamily(ModelError):
    """A model whose outputs match none of the known YOLO families."""


class ModelFetchError(ModelError):
    """The default model could not be fetched, verified or converted."""


class BackendUnavailable(StackError):
    """An inference backend whose runtime or device is missing on this machine."""


class RecordingError(StackError):
    """A recording that cannot be read or played: not MCAP, corrupt, or of unknown schemas."""


#: The longest message :func:`one_line` keeps (runtimes can print whole graphs in an error).
ONE_LINE_MAX_CHARS = 200


def one_line(exc: BaseException) -> str:
    """``exc``'s message on one line, at most :data:`ONE_LINE_MAX_CHARS` characters.

    For translating a library's error at the boundary: ``raise ModelError(f"...:
    {one_line(exc)}") from exc``; the full text stays on the chained exception.
    """
    text = " ".join(str(exc).split())
    return text if len(text) <= ONE_LINE_MAX_CHARS else text[: ONE_LINE_MAX_CHARS - 3] + "..."
