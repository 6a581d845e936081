"""The controller's contract: its counters, and what it and the operator's e-stop tool
(``zstack estop``, services/controller/estop_command.py) put and read. Imports only ``common``.

Only the controller puts ``cmd_vel``; only the ``estop`` principal the e-stop.
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import COMMON
from common.freshness import Verdict

# Its inputs, each counted by its fate (:func:`input_counter`): ``detections_in``,
# ``detections_stale`` ...; the detections' for each camera too when there are several.
DETECTIONS = "detections"
SCANS = "scans"
IN = "in"  # fresh, and the newest held
LATE = "late"  # fresh, but older than the one held
ESTOP_RELEASE_REFUSED = "estop_release_refused"
ESTOP_ZERO_AT_ONCE = "estop_zero_at_once"
COMMANDS_OUT = "commands_out"
COMMANDS_NONZERO = "commands_nonzero"

OUTCOMES = (IN, LATE, *(str(v) for v in Verdict if v is not Verdict.FRESH))


def input_counter(stream: str, outcome: str) -> str:
    """The counter of ``stream``'s (DETECTIONS, SCANS) messages with ``outcome`` (IN, LATE or
    a freshness verdict)."""
    return f"{stream}_{outcome}"


PER_CAMERA = frozenset(input_counter(DETECTIONS, o) for o in OUTCOMES)
COUNTERS = frozenset(
    {
        *COMMON,
        *PER_CAMERA,
        *(input_counter(SCANS, o) for o in OUTCOMES),
        ESTOP_RELEASE_REFUSED,
        ESTOP_ZERO_AT_ONCE,
        COMMANDS_OUT,
        COMMANDS_NONZERO,
    }
)

SERVICE = "controller"
#: The operator's e-stop tool's principal: it puts the e-stop and reads the controller's status.
ESTOP_PRINCIPAL = "estop"


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            keys.cmd_vel(),
            keys.controller_status(),
            read=(keys.all_detections(), keys.scan(), keys.estop()),
        )
    }


def estop_access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {ESTOP_PRINCIPAL: Access(put=(keys.estop(),), read=(keys.controller_status(),))}
