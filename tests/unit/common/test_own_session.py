"""own_session on a real process (a child of the test, run as a command would be): the command
goes on in a session of its own (its own autogroup, so its own share of the CPU), its exit code
and the signals a caller sends pass through the parent left in the caller's session."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from tests.polling import wait_for

REPO = Path(__file__).resolve().parents[3]
CHILD = """
import json, os, sys, threading
from common.priority import own_session
caller = os.getsid(0)
code = own_session()
if code is not None:
    raise SystemExit(code)
print(json.dumps({"caller": caller, "sid": os.getsid(0), "pid": os.getpid(),
                  "again": own_session()}), flush=True)
if sys.argv[1] == "wait":
    threading.Event().wait(60)
raise SystemExit(int(sys.argv[1]) if sys.argv[1] != "wait" else 0)
"""


def _start(arg: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", CHILD, arg], cwd=REPO, stdout=subprocess.PIPE, text=True
    )


def test_the_command_runs_in_a_session_of_its_own_and_its_code_comes_back() -> None:
    proc = _start("3")
    out, _ = proc.communicate(timeout=60)
    seen = json.loads(out)
    assert seen["sid"] == seen["pid"] != seen["caller"]  # a leader of a new session
    assert seen["again"] is None  # already a leader: no second fork
    assert proc.returncode == 3


def test_a_stop_sent_to_the_parent_reaches_the_command() -> None:
    proc = _start("wait")
    assert proc.stdout is not None
    seen = json.loads(proc.stdout.readline())
    os.kill(proc.pid, signal.SIGTERM)  # to the parent, as a caller would (Ctrl-C: SIGINT)
    assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    wait_for(lambda: not os.path.exists(f"/proc/{seen['pid']}"), 10, "the command to end")
