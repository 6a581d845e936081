"""leave_idle: a thread in SCHED_IDLE is put back in the normal class (Linux)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from common.priority import leave_idle, process_threads

pytestmark = pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux scheduling classes")


def test_an_idle_thread_is_put_back_in_the_normal_class_by_another() -> None:
    ready, done = threading.Event(), threading.Event()

    def idle() -> None:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        ready.set()
        done.wait(10)

    thread = threading.Thread(target=idle)
    thread.start()
    try:
        assert ready.wait(10)
        tid = thread.native_id
        assert tid is not None and os.sched_getscheduler(tid) == os.SCHED_IDLE
        assert leave_idle(tid) == "back in the normal class to finish"
        assert os.sched_getscheduler(tid) == os.SCHED_OTHER
    finally:
        done.set()
        thread.join()


def test_every_thread_of_the_process_is_put_back_those_a_library_started_included() -> None:
    # A thread started by an idle-class thread inherits the class (as Zenoh's runtime threads
    # do in the recorder): process_threads finds it without being told its id.
    started, done = threading.Event(), threading.Event()
    ids: list[int] = []

    def child() -> None:
        ids.append(threading.get_native_id())
        started.set()
        done.wait(10)

    def idle_parent() -> None:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        threading.Thread(target=child, daemon=True).start()
        done.wait(10)

    parent = threading.Thread(target=idle_parent)
    parent.start()
    try:
        assert started.wait(10)
        assert os.sched_getscheduler(ids[0]) == os.SCHED_IDLE
        assert ids[0] in process_threads()
        leave_idle(*process_threads())
        assert os.sched_getscheduler(ids[0]) == os.SCHED_OTHER
    finally:
        done.set()
        parent.join()


def test_another_process_is_put_back_every_thread_as_the_supervisor_does_at_stop() -> None:
    code = (
        "import os, sys, threading\n"
        "os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))\n"
        "threading.Thread(target=sys.stdin.read, daemon=True).start()\n"
        "print('idle', flush=True)\n"
        "sys.stdin.read()\n"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "idle"
        threads = process_threads(child.pid)
        assert len(threads) >= 2
        assert all(os.sched_getscheduler(t) == os.SCHED_IDLE for t in threads)
        assert leave_idle(*threads) == "back in the normal class to finish"
        assert all(os.sched_getscheduler(t) == os.SCHED_OTHER for t in threads)
    finally:
        child.kill()
        child.wait()
