"""Lowering a process's CPU priority, so that it takes only the time perception leaves over.

Two ways (Linux): ``nice`` (a smaller share of the CPU, still taken in the middle of an
inference) and ``SCHED_IDLE`` (runs only on a core that would otherwise be idle, and gives it up
as soon as anything else wants it). Either is set before any thread starts (Zenoh's included),
as each thread inherits it.

Both rank a process only against those in its own **session**: with the kernel's autogroup
scheduling (``/proc/sys/kernel/sched_autogroup_enabled``, on by default where it is built in),
the CPU is first shared fairly between sessions. That is why the supervisor starts every
service in a process group of its own but in the supervisor's session (common/spawn.py): a
recorder in a session of its own, however niced, took as much CPU in the middle of an inference
as it wanted, and slowed the detector by 5 to 10 % (docs/benchmarks.md).
"""

from __future__ import annotations

import os


def lower_priority(nice: int, idle: bool) -> str:
    """Raise this process's nice value by ``nice``, then, when ``idle``, put it in
    ``SCHED_IDLE``; returns what was done, for the log."""
    done = []
    if nice > 0:
        done.append(f"nice {os.nice(nice)}")
    if idle:
        try:
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
            done.append("SCHED_IDLE (only cores perception leaves idle)")
        except (AttributeError, OSError) as exc:  # not Linux, or refused: nice alone
            done.append(f"not SCHED_IDLE ({exc})")
    return ", ".join(done) or "unchanged"
