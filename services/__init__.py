"""The stack's services, one package each: ``python -m services.<name> serve --config FILE``."""

import os
import signal

from common.lifecycle import STOP_SIGNALS


def _stop_while_starting(_signum: int, _frame: object) -> None:
    raise SystemExit(0)


# A service that the supervisor started can be told to stop while it is still starting (the
# stack stopping early: another service failed, or Ctrl-C right after `make run`). Python's
# default SIGINT handler would end it with a KeyboardInterrupt traceback from some import, and
# a stop is not an error. So the supervisor starts each service with SIGINT and SIGTERM
# blocked (deploy/processes.py, common/spawn.py): a stop sent while the interpreter starts
# waits, pending, until here, where it ends the process quietly with exit code 0.
# common.lifecycle.stop_event() replaces these handlers once the service runs. The variable is
# set by the supervisor alone, so tests and tools that import services keep Python's handlers.
if os.environ.get("STACK_SUPERVISOR_PID"):
    for _sig in STOP_SIGNALS:
        signal.signal(_sig, _stop_while_starting)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
