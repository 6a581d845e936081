"""Every counter the metrics service reads by name is one the service that writes it declares
(its contract), so that renaming a counter cannot silently zero a figure."""

from __future__ import annotations

from types import ModuleType

from common import counters
from services.camera import contract as camera
from services.controller import contract as controller
from services.detector import contract as detector
from services.metrics import contract as metrics
from services.recorder import contract as recorder
from services.ros2 import contract as ros2
from services.sim import contract as sim
from services.viewer import contract as viewer

WRITERS: dict[str, ModuleType] = {
    "camera": camera,
    "controller": controller,
    "detector": detector,
    "metrics": metrics,
    "recorder": recorder,
    "ros2": ros2,
    "sim": sim,
    "viewer": viewer,
}


def test_every_counter_metrics_reads_is_declared_by_its_writer() -> None:
    undeclared = [
        f"{package}.{name}"
        for package, names in metrics.READS.items()
        for name in names
        if name not in WRITERS[package].COUNTERS
    ]
    assert undeclared == []


def test_every_per_camera_counter_metrics_reads_is_declared_per_camera() -> None:
    undeclared = [
        f"{package}.{name}.<camera>"
        for package, names in metrics.READS_PER_CAMERA.items()
        for name in names
        if name not in WRITERS[package].PER_CAMERA
    ]
    assert undeclared == []


def test_each_contract_declares_its_per_camera_counters_among_its_counters() -> None:
    for package, contract in WRITERS.items():
        assert contract.PER_CAMERA <= contract.COUNTERS, package


def test_the_metrics_modules_read_the_detector_counters_they_name() -> None:
    # what services/metrics/cameras.py and aggregate.py take from the detector's counters
    from services.metrics import aggregate, cameras

    read = {*cameras.DROP_COLUMNS, cameras.WORKER_COUNTER, cameras.SERVING_COUNTER}
    read |= {*cameras.BATCH_COUNTERS, *aggregate._DETECTOR_DELTAS}
    assert read <= set(metrics.READS["detector"])


def test_the_contracts_drop_verdicts_are_the_freshness_gates() -> None:
    from common.freshness import Verdict

    dropped = tuple(str(v) for v in Verdict if v is not Verdict.FRESH)
    assert dropped == counters.DROP_VERDICTS
