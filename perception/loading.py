"""Serving's load of what was prepared ahead: what the detector service runs at start.

:func:`load` opens what preparation (preparing.py, ``zstack prepare``) made, the fast
profile's cached choice included, and builds nothing: what is missing raises NotPrepared, one
line saying what to run. Loading and preparing are two functions in two modules: nothing this
module imports reaches the quantizer (tests/unit/test_imports.py checks it).
"""

from __future__ import annotations

from perception.fast_profile import choose_fast
from perception.pipeline import Detector
from perception.settings import DetectorSpec
from perception.variants import open_located


def load(s: DetectorSpec, max_batch: int = 1) -> tuple[Detector, str]:
    """The detector for ``s``, for batches of up to ``max_batch`` frames, opened from what
    preparation made (the fast profile's cached choice included), with a note on what was
    chosen; NotPrepared names what is missing."""
    if s.profile == "fast":
        variant, why = choose_fast(s)
        det, note = open_located(variant.settings(s), max_batch)
        return det, f"{why}; {note}" if note else why
    return open_located(s, max_batch)
