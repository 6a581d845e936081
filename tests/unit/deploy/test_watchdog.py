from __future__ import annotations

import pytest

from common.errors import ConfigError
from deploy.watchdog import HEARTBEAT_SERVICES, Observation, check_settings, judge
from services.controller.contract import ControllerSettings
from services.detector.contract import DetectorSettings
from stack.config import Config, SupervisorSettings

GRACE, PROGRESS = 2.0, 5.0


def verdict(seen: Observation, now: float, name: str = "detector") -> str | None:
    return judge(name, seen, now, grace_s=GRACE, progress_s=PROGRESS)


def test_a_service_with_its_token_and_a_heartbeat_is_fine() -> None:
    seen = Observation(ready_at=10.0, token_lost_at=None, last_progress=99.0)
    assert verdict(seen, 100.0) is None


def test_a_vanished_token_is_hung_only_after_the_grace() -> None:
    seen = Observation(ready_at=10.0, token_lost_at=50.0, last_progress=51.0)
    assert verdict(seen, 51.9) is None
    why = verdict(seen, 52.5)
    assert why is not None and "liveliness token has been gone for 2.5 s" in why


def test_a_token_lost_in_an_earlier_run_does_not_count() -> None:
    seen = Observation(ready_at=60.0, token_lost_at=50.0, last_progress=61.0)
    assert verdict(seen, 62.0) is None


def test_a_silent_work_loop_is_hung_after_the_progress_timeout() -> None:
    seen = Observation(ready_at=10.0, token_lost_at=None, last_progress=20.0)
    assert verdict(seen, 24.9) is None
    why = verdict(seen, 25.0)
    assert why is not None and "no counters for 5.0 s" in why


def test_a_loop_that_never_beat_since_it_was_ready_is_hung() -> None:
    # Heartbeats of the run before the restart (at 5) are not this run's.
    seen = Observation(ready_at=10.0, token_lost_at=None, last_progress=5.0)
    assert verdict(seen, 14.0) is None
    assert verdict(seen, 15.5) is not None


def test_metrics_has_no_work_loop_and_is_judged_by_its_token_alone() -> None:
    assert "metrics" not in HEARTBEAT_SERVICES
    quiet = Observation(ready_at=10.0, token_lost_at=None, last_progress=None)
    assert verdict(quiet, 1000.0, "metrics") is None
    assert verdict(quiet, 1000.0, "controller") is not None


def test_a_zero_progress_timeout_turns_the_heartbeat_check_off() -> None:
    quiet = Observation(ready_at=10.0, token_lost_at=None, last_progress=None)
    assert judge("detector", quiet, 1000.0, grace_s=GRACE, progress_s=0.0) is None


def test_a_progress_timeout_shorter_than_two_counters_periods_is_refused() -> None:
    check_settings(Config(supervisor=SupervisorSettings(watchdog_progress_s=2.0)))
    check_settings(Config(supervisor=SupervisorSettings(watchdog_progress_s=0.0)))
    slow = Config(
        supervisor=SupervisorSettings(watchdog_progress_s=5.0),
        detector=DetectorSettings(counters_period_s=3.0),
    )
    with pytest.raises(ConfigError, match=r"watchdog_progress_s \(5 s\) must be at least 2 x"):
        check_settings(slow)
    with pytest.raises(ConfigError, match=r"controller\.counters_period_s"):
        check_settings(
            Config(
                supervisor=SupervisorSettings(watchdog_progress_s=3.0),
                controller=ControllerSettings(counters_period_s=2.0),
            )
        )
    with pytest.raises(ConfigError, match="watchdog_progress_s"):
        SupervisorSettings(watchdog_progress_s=-1.0)


def test_every_camera_process_beats_as_the_camera_does() -> None:
    # camera_rear (a further camera's process) is watched for its heartbeat like "camera".
    quiet = Observation(ready_at=10.0, token_lost_at=None, last_progress=None)
    assert verdict(quiet, 1000.0, "camera") is not None
    assert verdict(quiet, 1000.0, "camera_rear") is not None
