"""The detector's contract: its counters and what each worker puts, announces, serves and reads.

Imports only ``common``: the config, the access rules (stack/) and the metrics service read it
without the detector's internals. Each worker (``detector``, ``detector_2``,
``detector_<worker_id>`` ...) counts totals under the plain names and each camera's under
``<name>.<camera>`` (common/counters.py::per_camera) for those in :data:`PER_CAMERA`.
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import BAD_INPUT, COMMON
from common.freshness import Verdict

# -- counters --------------------------------------------------------------------------------
FRAMES_IN = "frames_in"  # frames offered: heard on a camera this worker serves
FRAMES_MISSED = "frames_missed"  # gaps in a camera's frame numbering
DROPPED = "dropped"  # frames replaced in the slot by a newer one before detection
FRAMES_OVERSIZE = "frames_oversize"  # over detector.max_frame_pixels
NONFINITE_OUTPUTS = "nonfinite_outputs"  # the model's output was not finite: nothing published
DETECTIONS_OUT = "detections_out"
BATCHES = "batches"  # inference runs (rounds) ...
BATCHED_FRAMES = "batched_frames"  # ... and the frames in them: the mean batch is their ratio
TRACKER_STAMP_JUMPS = "tracker_stamp_jumps"
TRACKER_RESETS = "tracker_resets"
# The pool (gauges: moved by their difference, so they read as the current value).
SERVING = "serving"  # cameras served; per camera 1 while it serves the camera
POOL_MEMBERS = "pool_members"
POOL_LOAD_PERMILLE = "pool_load_permille"  # its cameras' share of every camera's pixel rate
POOL_WARNINGS = "pool_warnings"
CAMERAS_GAINED = "cameras_gained"  # hand-overs
CAMERAS_LOST = "cameras_lost"
POOL_RESIGNED = "pool_resigned"  # left the pool on a stalled detection loop

#: The pool's gauges (set, not counted up).
POOL_GAUGES = (SERVING, POOL_MEMBERS, POOL_LOAD_PERMILLE, POOL_WARNINGS)


def frames_judged(verdict: Verdict) -> str:
    """The counter of frames dropped as they leave the slot for ``verdict`` (not fresh)."""
    return f"frames_{verdict}"


_JUDGED = tuple(frames_judged(v) for v in Verdict if v is not Verdict.FRESH)

#: Counted for each camera too, as ``<name>.<camera>``.
PER_CAMERA = frozenset(
    {
        FRAMES_IN,
        FRAMES_MISSED,
        DROPPED,
        BAD_INPUT,
        FRAMES_OVERSIZE,
        *_JUDGED,
        NONFINITE_OUTPUTS,
        DETECTIONS_OUT,
        TRACKER_STAMP_JUMPS,
        TRACKER_RESETS,
        SERVING,
        CAMERAS_GAINED,
        CAMERAS_LOST,
    }
)
#: Every counter a worker publishes (plain names; see PER_CAMERA for the per-camera ones).
COUNTERS = frozenset(
    {
        *COMMON,
        *PER_CAMERA,
        BATCHES,
        BATCHED_FRAMES,
        POOL_MEMBERS,
        POOL_LOAD_PERMILLE,
        POOL_WARNINGS,
        POOL_RESIGNED,
    }
)


# -- the bus ---------------------------------------------------------------------------------
def access(shape: Shape) -> dict[str, Access]:
    """Each worker reads frames and puts detections, never frames: every camera's, as any
    worker may come to serve any camera (services/detector/pool.py). Its tokens are its own
    only: its health, its pool membership and its serving tokens under its own name, so that
    no worker can pose as another, or as many, and skew the assignment or its audit. It serves
    the model's description on each camera's info key."""
    keys = shape.keys
    return {
        w: service_access(
            keys,
            w,
            *(keys.detections(c) for c in shape.cameras),
            read=(keys.all_frames(),),
            token=(keys.health(w), keys.pool_member(w), keys.pool_serving_of(w)),
            serve=(keys.all_detector_info(),),
        )
        for w in dict.fromkeys(shape.workers)
    }
