"""Every setting is bounded by a range a real robot could want, checked at start-up with one
line that names the setting, the value, the range and (for an override) the variable."""

from __future__ import annotations

import dataclasses
import math
import threading
import time
import typing
from typing import Any

import pytest

from common.errors import ConfigError
from common.setting_checks import (
    Length,
    Range,
    check_bounds,
    check_lengths,
    declared_bounds,
    declared_lengths,
    range_text,
)
from common.settings import DEFAULT_CONFIG, REPO_ROOT
from services.controller.service import STOP_POLL_S, wait_either
from stack.config import Config
from stack.config_file import load_config

# [cameras.<name>] are [camera] tables (CameraSettings): the camera table covers them.
TABLES = {f.name: f.type for f in dataclasses.fields(Config) if f.name not in ("path", "cameras")}
HINTS = typing.get_type_hints(Config)
# Checked by rules of their own: [w, h] within 1..MAX_IMAGE_SIDE or [0, 0] (keep the size);
# each service named at most once.
OWN_RULE = {"camera.resize", "supervisor.services"}


@pytest.mark.parametrize(
    "variable, value, line",
    [
        # The absurd values of issue 13, each accepted before.
        ("STACK__SIM__LASER_RAYS", "200000", "sim.laser_rays must be within 2..10000, got 200000"),
        (
            "STACK__CONTROLLER__CONTROL_RATE_HZ",
            "1e-9",
            "controller.control_rate_hz must be within 1..1000 Hz, got 1e-09",
        ),
        (
            "STACK__CONTROLLER__DETECTION_TIMEOUT_S",
            "1e9",
            "controller.detection_timeout_s must be within 0.01..10 s, got 1000000000.0",
        ),
        (
            "STACK__CONTROLLER__MAX_LINEAR",
            "1000",
            "controller.max_linear must be within 0.01..5 m/s, got 1000.0",
        ),
    ],
)
def test_the_absurd_settings_of_issue_13_are_one_line_blaming_the_variable(
    variable: str, value: str, line: str
) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(DEFAULT_CONFIG, environ={variable: value})
    assert str(err.value) == f"{variable}: {line}"


def test_the_same_value_in_a_file_is_blamed_on_the_setting(tmp_path: Any) -> None:
    path = tmp_path / "stack.toml"
    path.write_text("[controller]\nmax_linear = 1000\n")
    with pytest.raises(ConfigError) as err:
        load_config(path, environ={})
    assert str(err.value) == "controller.max_linear must be within 0.01..5 m/s, got 1000.0"


def _kind(hint: Any) -> str:
    """'number', 'numbers' (a tuple of them), 'names' (a tuple of str) or 'other'."""
    if hint in (int, float):
        return "number"
    if typing.get_origin(hint) is tuple:
        items = {a for a in typing.get_args(hint) if a is not Ellipsis}
        if items <= {int, float}:
            return "numbers"
        if items == {str}:
            return "names"
    return "other"


def _fields() -> list[tuple[str, str, Any]]:
    out = []
    for table in TABLES:
        for name, hint in typing.get_type_hints(HINTS[table]).items():
            out.append((table, name, hint))
    return out


def test_every_numeric_and_list_setting_has_a_declared_range() -> None:
    unbounded = []
    for table, name, hint in _fields():
        cls = HINTS[table]
        kind = _kind(hint)
        if f"{table}.{name}" in OWN_RULE:
            continue
        if kind in ("number", "numbers") and name not in declared_bounds(cls):
            unbounded.append(f"{table}.{name}")
        if kind == "names" and name not in declared_lengths(cls):
            unbounded.append(f"{table}.{name} (length)")
    assert unbounded == []


def _out_of_range(default: Any, lo: float, hi: float) -> list[Any]:
    """Values just outside ``lo..hi`` (and NaN for a float), shaped like ``default``."""
    if isinstance(default, tuple):
        return [tuple([hi + 1] * len(default)), tuple([lo - 1] * len(default))]
    if isinstance(default, int):
        return [int(hi) + 1, math.ceil(lo) - 1]
    step = max(abs(hi), 1e-3)
    return [hi + step, lo - max(abs(lo), 1e-3), math.nan, math.inf]


@pytest.mark.parametrize("table", sorted(t for t in TABLES if declared_bounds(HINTS[t])))
def test_each_bound_is_enforced_and_names_the_setting_and_its_range(table: str) -> None:
    cls = HINTS[table]
    default = cls()
    for name, (lo, hi) in declared_bounds(cls).items():
        value = getattr(default, name)
        assert all(lo <= v <= hi for v in (value if isinstance(value, tuple) else (value,)))
        for bad in _out_of_range(getattr(default, name), lo, hi):
            with pytest.raises(ConfigError) as err:
                cls(**{name: bad})
            line = str(err.value)
            assert line.startswith(f"{table}.{name} must "), line
            assert "\n" not in line and " within " in line and ".." in line, line


def test_list_lengths_are_bounded() -> None:
    line = r"^STACK__DETECTOR__CLASSES: detector\.classes must have 0\.\.2000 items, got 2001 items"
    with pytest.raises(ConfigError, match=line):
        load_config(DEFAULT_CONFIG, environ={"STACK__DETECTOR__CLASSES": str(["c"] * 2001)})
    with pytest.raises(ConfigError, match=r"controller\.target_classes must have 1\.\.100 items"):
        load_config(DEFAULT_CONFIG, environ={"STACK__CONTROLLER__TARGET_CLASSES": "[]"})
    with pytest.raises(ConfigError, match=r"^STACK__ROS2__ROUTER: ros2\.router must have"):
        load_config(DEFAULT_CONFIG, environ={"STACK__ROS2__ROUTER": "[]"})


def test_the_simulator_waits_only_for_services_that_exist() -> None:
    with pytest.raises(ConfigError, match=r"^STACK__SIM__WAIT_FOR: sim\.wait_for must name"):
        load_config(DEFAULT_CONFIG, environ={"STACK__SIM__WAIT_FOR": '["detectr"]'})


def test_the_restart_backoff_cap_is_not_below_its_start() -> None:
    with pytest.raises(ConfigError, match="restart_backoff_max_s"):
        load_config(DEFAULT_CONFIG, environ={"STACK__SUPERVISOR__RESTART_BACKOFF_MAX_S": "0.1"})


def test_a_control_period_never_holds_back_a_stop() -> None:
    """The control loop waits for new detections or the next tick; a stop (SIGTERM) must end
    that wait within STOP_POLL_S, however long the period (it once waited 1/rate seconds)."""
    wake, stop = threading.Event(), threading.Event()
    threading.Timer(0.2, stop.set).start()
    start = time.monotonic()
    wait_either(wake, stop, 1e9)
    assert time.monotonic() - start < 0.2 + STOP_POLL_S + 1.0  # a loaded machine's margin
    assert stop.is_set() and not wake.is_set()
    # A new message still wakes it at once, and a short period still times out.
    stop.clear()
    threading.Timer(0.05, wake.set).start()
    wait_either(wake, stop, 1e9)
    assert wake.is_set()
    wake.clear()
    start = time.monotonic()
    wait_either(wake, stop, 0.05)
    assert 0.04 <= time.monotonic() - start < 1.0


def test_docs_configuration_states_every_range_as_the_code_does() -> None:
    doc = (REPO_ROOT / "docs" / "configuration.md").read_text()
    missing = []
    for table in TABLES:
        cls = HINTS[table]
        for name, (lo, hi) in declared_bounds(cls).items():
            row = f"| `{table}.{name}` | {range_text(name, lo, hi)} |"
            missing += [] if row in doc else [row]
        for name, (lo, hi) in declared_lengths(cls).items():
            row = f"| `{table}.{name}` | {range_text('', lo, hi)} items |"
            missing += [] if row in doc else [row]
    assert missing == []


def test_each_range_is_declared_on_its_field_and_no_table_repeats_it() -> None:
    """Bounds live on the fields (``Annotated[float, Range(lo, hi)]``), once: no settings class
    keeps a BOUNDS or LENGTHS table beside them."""
    classes = {HINTS[t] for t in TABLES} | {c for t in TABLES for c in HINTS[t].__mro__}
    tables = sorted(
        f"{c.__name__}.{name}"
        for c in classes
        for name in vars(c)
        if name.endswith(("BOUNDS", "LENGTHS"))
    )
    assert tables == []


def test_a_setting_range_needs_both_ends_and_a_base_checks_its_own_fields() -> None:
    @dataclasses.dataclass(frozen=True)
    class Base:
        rate_hz: typing.Annotated[float, Range(0.1, 10)] = 1.0

        def __post_init__(self) -> None:
            check_bounds(self, "base", Base)

    @dataclasses.dataclass(frozen=True)
    class Derived(Base):
        names: typing.Annotated[tuple[str, ...], Length(1, 2)] = ("a",)

        def __post_init__(self) -> None:
            Base.__post_init__(self)
            check_lengths(self, "derived", Derived)

    assert declared_bounds(Derived) == {"rate_hz": (0.1, 10)}
    assert declared_lengths(Derived) == {"names": (1, 2)}
    with pytest.raises(ConfigError, match=r"^base\.rate_hz must be within 0\.1\.\.10 Hz, got 20"):
        Derived(rate_hz=20)
    with pytest.raises(ConfigError, match=r"^derived\.names must have 1\.\.2 items, got \[\]"):
        Derived(names=())

    @dataclasses.dataclass(frozen=True)
    class HalfOpen:
        n: typing.Annotated[int, Range(lo=0)] = 0

    with pytest.raises(TypeError, match="needs both bounds"):
        declared_bounds(HalfOpen)
