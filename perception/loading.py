"""Model preparation ahead of serving, and serving's load of what it made.

:func:`prepare_for` does every preparation settings need, with progress: the default model
fetched and converted, rebuilt at the input size, the INT8 model quantized, and, for the fast
profile, the variants measured and the chosen one prepared (``zstack prepare``). Ctrl-C or
SIGTERM stops it at once, leaving no file half-written (modelprep writes through scratch
files). :func:`load` is what the detector service runs at start: it opens what was prepared
and builds nothing; what is missing raises NotPrepared, one line saying what to run.
"""

from __future__ import annotations

from common.lifecycle import Progress, print_progress
from perception.fast_profile import Measure, choose_fast
from perception.pipeline import Detector
from perception.variants import Prepared, open_located, prepare
from services.detector.contract import DetectorSettings


def prepare_for(
    s: DetectorSettings, progress: Progress = print_progress, *, measure: Measure | None = None
) -> tuple[Prepared, str]:
    """Prepare what serving ``s`` loads; what it loads, and why that variant ("" unless the
    fast profile chose it). ``measure`` times the fast profile's candidates when their figures
    are not cached (NotPrepared without it)."""
    why = ""
    if s.profile == "fast":
        variant, why = choose_fast(s, progress, measure=measure)
        progress(why)
        s = variant.settings(s)
    return prepare(s, progress), why


def load(s: DetectorSettings, max_batch: int = 1) -> tuple[Detector, str]:
    """The detector for ``s``, for batches of up to ``max_batch`` frames, opened from what
    :func:`prepare_for` made (the fast profile's cached choice included), with a note on what
    was chosen; NotPrepared names what is missing."""
    if s.profile == "fast":
        variant, why = choose_fast(s)
        det, note = open_located(variant.settings(s), max_batch)
        return det, f"{why}; {note}" if note else why
    return open_located(s, max_batch)
