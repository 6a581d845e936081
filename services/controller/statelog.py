"""How the controller logs its changes of state: an e-stop or a fault always; the others
rate-limited, since detections that go stale between one and the next flip the state several
times a second (the first changes in full, then one summary per period)."""

from __future__ import annotations

import logging

from common.contracts import ControllerState
from common.ratelimit import LogLimiter
from services.controller.policy import VelocityCommand

#: The limiter's key for state changes: its summaries read "state changes: N more not logged".
STATE_CHANGES = "state changes"


def log_state(log: logging.Logger, limiter: LogLimiter, cmd: VelocityCommand) -> None:
    """Log a change of state: an e-stop or a fault always, the others rate-limited."""
    if cmd.state in (ControllerState.ESTOP, ControllerState.FAULT):
        log.info("state %s: %s", cmd.state, cmd.reason)
        return
    admit = limiter.admit(STATE_CHANGES, f"to {cmd.state}")
    if admit.summary:
        log.info("%s", admit.summary)
    if admit.log:
        log.info("state %s: %s", cmd.state, cmd.reason)
