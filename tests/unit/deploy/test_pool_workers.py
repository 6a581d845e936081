"""A detector pool under the supervisor: one process per worker (``detector.workers``), each
with one name (service, process, pool id, principal), watched as a detector; and its access
rules."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from common.errors import ConfigError
from common.keys import Keys
from common.security import stack_principals
from common.settings import detector_service, is_detector_service, service_package
from deploy.processes import service_command, stack_processes
from deploy.watchdog import Observation, judge
from services.detector.contract import DetectorSettings
from stack.access import access_control
from stack.access_table import may_announce, may_put
from stack.config import Config
from stack.config_file import load_config


def _config(tmp_path: Path, text: str) -> Config:
    path = tmp_path / "stack.toml"
    path.write_text(text)
    return load_config(path, environ={})


def test_one_worker_is_the_one_detector(tmp_path: Path) -> None:
    config = _config(tmp_path, '[supervisor]\nservices = ["detector"]\n')
    assert config.detector_services == ("detector",)
    assert stack_processes(config) == [
        ("detector", [sys.executable, "-m", "services.detector", "serve", "--config", config.path])
    ]


def test_n_workers_are_n_processes(tmp_path: Path) -> None:
    config = _config(
        tmp_path, '[supervisor]\nservices = ["detector", "metrics"]\n[detector]\nworkers = 3\n'
    )
    assert config.detector_services == ("detector", "detector_2", "detector_3")
    assert stack_processes(config) == [
        ("detector", service_command("detector", config.path)),
        ("detector_2", [*service_command("detector", config.path), "--worker", "detector_2"]),
        ("detector_3", [*service_command("detector", config.path), "--worker", "detector_3"]),
        ("metrics", service_command("metrics", config.path)),
    ]


def test_host_qualified_worker_names(tmp_path: Path) -> None:
    config = _config(
        tmp_path,
        '[supervisor]\nservices = ["detector"]\n[detector]\nworkers = 2\nworker_id = "gpu"\n',
    )
    assert config.detector_services == ("detector_gpu", "detector_gpu_2")
    # Each is started by its name, and runs from services/detector.
    assert stack_processes(config) == [
        (w, [*service_command("detector", config.path), "--worker", w])
        for w in ("detector_gpu", "detector_gpu_2")
    ]
    assert {service_package(w) for w in config.detector_services} == {"detector"}
    assert detector_service(1) == "detector" and detector_service(3, "a") == "detector_a_3"


@pytest.mark.parametrize("bad", ["a/b", "*", "-x", "2", "1a", "Gpu", "gpu_2", "gpu_", "a" * 25])
def test_a_worker_id_must_be_one_key_chunk(bad: str) -> None:
    with pytest.raises(ConfigError, match="worker_id") as err:
        DetectorSettings(worker_id=bad)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("good", ["", "a", "gpu", "robot1", "gpu_box", "a" * 24])
def test_worker_ids_that_name_workers(good: str) -> None:
    DetectorSettings(worker_id=good)  # empty: detector, detector_2 ...
    assert is_detector_service(detector_service(8, good))


def test_detector_service_names() -> None:
    for name in ("detector", "detector_2", "detector_gpu", "detector_gpu_8"):
        assert is_detector_service(name)
    for name in ("detector_", "detectors", "camera", "detector/x", "detector_A", "detector_*",
                 "detector_" + "a" * 41, "", "rogue"):  # fmt: skip
        assert not is_detector_service(name), name


def test_every_worker_is_watched_as_a_detector() -> None:
    assert service_package("detector_2") == "detector"
    seen = Observation(ready_at=0.0, token_lost_at=None, last_progress=None)
    assert judge("detector_2", seen, 30.0, grace_s=2.0, progress_s=20.0) is not None


def test_each_worker_is_a_principal_that_announces_only_itself() -> None:
    keys = Keys("stack")
    cameras = {"front": "camera", "rear": "camera_rear"}
    workers = ("detector_a", "detector_a_2")
    principals = stack_principals(cameras, workers)
    assert "detector" not in principals
    assert principals[principals.index("ros2") + 1 :][:2] == workers  # in detector's place
    acl = access_control(keys, cameras, "password", workers=workers)
    everyone = next(s for s in acl["subjects"] if s["id"] == "everyone")
    assert {f"stack/{w}" for w in workers} <= set(everyone["usernames"])
    for w in workers:
        rule = next(r for r in acl["rules"] if r["id"] == f"{w}_token")
        assert set(rule["key_exprs"]) == {
            keys.health(w), keys.pool_member(w), keys.worker_announcements_of(w),
            keys.pool_serving_of(w),
        }  # fmt: skip
        assert set(may_announce(keys, cameras, w, workers=workers)) == set(rule["key_exprs"])
        # Every camera's detections (any worker may serve any camera), its counters, no frame.
        assert set(may_put(keys, cameras, w, workers=workers)) == {
            keys.detections("front"), keys.detections("rear"), keys.counters(w),
        }  # fmt: skip
    # The one detector of a one-worker stack is as it was.
    acl = access_control(keys, "front", "password")
    rule = next(r for r in acl["rules"] if r["id"] == "detector_token")
    assert set(rule["key_exprs"]) == {
        keys.health("detector"), keys.pool_member("detector"),
        keys.worker_announcements_of("detector"), keys.pool_serving_of("detector"),
    }  # fmt: skip
