"""The supervisor's watchdog: is a running service hung? Pure: the supervisor brings the clock
and what it saw on the bus (deploy/supervisor.py), and acts on the verdict (deploy/processes.py).

Two signals, per service the supervisor started itself (never a service on another host), and
per camera process (``camera``, ``camera_<name>``: each has its own token and counters):

- **Its liveliness token** ``<prefix>/health/<service>``. A service holds it from ``ready()``
  until it stops. It vanishes when the process dies, is frozen (SIGSTOP: Zenoh's lease, about
  10 s, expires) or loses its link to the supervisor. Gone for ``watchdog_grace_s`` while the
  process still runs: hung.
- **Progress of its work loop**: its counters ``<prefix>/counters/<service>``. Every service with
  a work loop calls ``Node.publish_counters()`` on each pass of that loop, whether or not input
  came (the detector's loop wakes every 0.1 s on an empty mailbox), and the call publishes at
  most every ``counters_period_s`` (1 s). So the counters are the loop's heartbeat: they stop
  when the loop blocks (a stuck inference, a camera read that never returns, a deadlock) even
  while Zenoh's own threads keep the token alive. None for ``watchdog_progress_s`` after the
  service was ready: hung. The metrics service has no work loop (it aggregates in Zenoh's
  callbacks and publishes no counters): only its token is watched.

The default ``watchdog_progress_s`` (20 s) stays above Zenoh's lease (10 s): with the link to
another host cut, a detector's loop was seen to go without counters for about 10 s (until the
lease dropped the dead peers), and must not be restarted for that (tests/integration/
test_two_hosts.py).

A hung service is then stopped (SIGTERM and SIGCONT, SIGKILL after ``stop_timeout_s``) and
restarted with the same backoff as a crash.
"""

from __future__ import annotations

from dataclasses import dataclass

from common.errors import ConfigError
from common.settings import service_package
from stack.config import Config
from stack.contracts import heartbeat_services

# Services whose work loop publishes counters on every pass (their heartbeat, see above; their
# contracts' HEARTBEAT); by package: every camera's process (camera, camera_<name>) beats as the
# camera does.
HEARTBEAT_SERVICES = heartbeat_services()
# The heartbeat timeout must span this many counters periods, so that a late sample (TELEMETRY
# is dropped under congestion) or a slow pass on a loaded machine is not taken for a hang.
MIN_PERIODS = 2.0
# common/node.py's default counters period, used by the camera, the simulator and the bridge.
NODE_COUNTERS_PERIOD_S = 1.0


@dataclass(frozen=True, slots=True)
class Observation:
    """What the supervisor knows of one service at ``now`` (monotonic seconds).

    ``ready_at``: when the supervisor saw it ready (its token appeared) since its last start.
    ``token_lost_at``: when its token vanished, None while it is present.
    ``last_progress``: when its last counters arrived, None if none ever did.
    """

    ready_at: float
    token_lost_at: float | None
    last_progress: float | None


def judge(
    name: str, seen: Observation, now: float, *, grace_s: float, progress_s: float
) -> str | None:
    """Why ``name`` counts as hung at ``now``, or None while it is fine.

    Anything seen before ``ready_at`` belongs to an earlier run and is ignored. ``progress_s``
    0 turns the progress check off.
    """
    if seen.token_lost_at is not None and seen.token_lost_at >= seen.ready_at:
        gone = now - seen.token_lost_at
        if gone >= grace_s:
            return f"its liveliness token has been gone for {gone:.1f} s"
    if progress_s > 0 and service_package(name) in HEARTBEAT_SERVICES:
        quiet = now - max(seen.ready_at, seen.last_progress or seen.ready_at)
        if quiet >= progress_s:
            return f"its work loop has published no counters for {quiet:.1f} s"
    return None


def check_settings(config: Config) -> None:
    """Refuse a progress timeout that a healthy service's heartbeat period could trip."""
    timeout = config.supervisor.watchdog_progress_s
    if timeout == 0:
        return
    periods = {
        "detector.counters_period_s": config.detector.counters_period_s,
        "controller.counters_period_s": config.controller.counters_period_s,
        "the other services' counters period": NODE_COUNTERS_PERIOD_S,
    }
    for name, period in periods.items():
        if timeout < MIN_PERIODS * period:
            raise ConfigError(
                f"supervisor.watchdog_progress_s ({timeout:g} s) must be at least "
                f"{MIN_PERIODS:g} x {name} ({period:g} s), or 0 to turn the check off"
            )
