"""leave_idle: a thread in SCHED_IDLE is put back in the normal class (Linux)."""

from __future__ import annotations

import os
import threading

import pytest

from common.priority import leave_idle

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
