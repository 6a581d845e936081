"""A detector pool under the supervisor: one process per worker (``detector.workers``), each
named as its service, with its worker id, watched as a detector; and its token's access rule."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from common.config_file import load_config
from common.errors import ConfigError
from common.keys import Keys
from common.security import access_control
from common.settings import Config, DetectorSettings, service_package
from deploy.processes import service_command, stack_processes
from deploy.watchdog import Observation, judge


def _config(tmp_path: Path, text: str) -> Config:
    path = tmp_path / "stack.toml"
    path.write_text(text)
    return load_config(path, environ={})


def test_one_worker_is_the_one_detector(tmp_path: Path) -> None:
    config = _config(tmp_path, '[supervisor]\nservices = ["detector"]\n')
    assert config.detector_services == {"detector": "detector"}
    assert stack_processes(config) == [
        ("detector", [sys.executable, "-m", "services.detector", "serve", "--config", config.path])
    ]


def test_n_workers_are_n_processes(tmp_path: Path) -> None:
    config = _config(
        tmp_path, '[supervisor]\nservices = ["detector", "metrics"]\n[detector]\nworkers = 3\n'
    )
    assert config.detector_services == {
        "detector": "detector", "detector_2": "detector_2", "detector_3": "detector_3",
    }  # fmt: skip
    assert stack_processes(config) == [
        ("detector", service_command("detector", config.path)),
        ("detector_2", [*service_command("detector", config.path), "--worker", "detector_2"]),
        ("detector_3", [*service_command("detector", config.path), "--worker", "detector_3"]),
        ("metrics", service_command("metrics", config.path)),
    ]


def test_host_qualified_worker_ids(tmp_path: Path) -> None:
    config = _config(tmp_path, '[detector]\nworkers = 2\nworker_id = "robot1"\n')
    assert config.detector_services == {"detector": "robot1", "detector_2": "robot1_2"}


@pytest.mark.parametrize("bad", ["", "a/b", "*", "-x"])
def test_a_worker_id_must_be_one_key_chunk(bad: str) -> None:
    if bad == "":
        DetectorSettings(worker_id=bad)  # empty: the service name
        return
    with pytest.raises(ConfigError, match="worker_id"):
        DetectorSettings(worker_id=bad)


def test_every_worker_is_watched_as_a_detector() -> None:
    assert service_package("detector_2") == "detector"
    seen = Observation(ready_at=0.0, token_lost_at=None, last_progress=None)
    assert judge("detector_2", seen, 30.0, grace_s=2.0, progress_s=20.0) is not None


def test_the_detector_may_declare_its_pool_tokens() -> None:
    keys = Keys("stack")
    acl = access_control(keys, "front", "password", pool_workers=("robot1", "robot1_2"))
    rule = next(r for r in acl["rules"] if r["id"] == "detector_token")
    assert set(rule["key_exprs"]) == {
        keys.health("detector"), keys.pool_member("robot1"), keys.pool_member("robot1_2"),
    }  # fmt: skip
