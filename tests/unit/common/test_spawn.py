"""The one spawner: a child in a process group of its own within our session, started with the
stop signals blocked when asked, stopped by a signal, a deadline, then a kill."""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys

from common.spawn import spawn, stop_child, wait_or_kill
from tests.unit.packages import PACKAGES, ROOT

READY = "import signal, sys\n{setup}\nprint('ready', flush=True)\nsignal.pause()"


def _child(setup: str = "", *, blocked: bool = False) -> subprocess.Popen[bytes]:
    argv = [sys.executable, "-c", READY.format(setup=setup)]
    proc = spawn(argv, stdout=subprocess.PIPE, stop_signals_blocked=blocked)
    assert proc.stdout is not None and proc.stdout.readline() == b"ready\n"
    return proc


def _blocked_signals(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1], 16) for line in f if line.startswith("SigBlk"))


def test_a_child_has_a_process_group_of_its_own_in_our_session() -> None:
    proc = _child()
    try:
        assert os.getpgid(proc.pid) == proc.pid != os.getpgid(0)
        assert os.getsid(proc.pid) == os.getsid(0)
    finally:
        proc.kill()
        proc.wait()


def test_a_child_starts_with_the_stop_signals_blocked_only_when_asked() -> None:
    stop_bits = (1 << (signal.SIGINT - 1)) | (1 << (signal.SIGTERM - 1))
    before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    for blocked in (False, True):
        proc = _child(blocked=blocked)
        try:
            assert bool(_blocked_signals(proc.pid) & stop_bits == stop_bits) is blocked
        finally:
            proc.kill()
            proc.wait()
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == before  # ours is left as it was


def test_stop_child_sends_sigint_and_says_it_exited_in_time() -> None:
    proc = _child("signal.signal(signal.SIGINT, lambda *_: sys.exit(0))")
    assert stop_child(proc, timeout_s=10) is True
    assert proc.returncode == 0


def test_wait_or_kill_kills_what_is_still_running_at_the_deadline() -> None:
    proc = _child("signal.signal(signal.SIGINT, signal.SIG_IGN)")
    assert stop_child(proc, timeout_s=0.2) is False
    assert proc.returncode == -signal.SIGKILL
    assert wait_or_kill(proc, 0.0) is True  # reaped: nothing left to wait for


def test_no_production_module_but_common_spawn_starts_a_long_running_child() -> None:
    wrong = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if path == ROOT / "common" / "spawn.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Call) and ast.unparse(node.func).endswith("Popen"):
                    wrong.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert wrong == [], "start children with common.spawn.spawn:\n" + "\n".join(wrong)
