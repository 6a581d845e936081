"""Where a tool's private stacks listen (tools/ports.py): free ports by default, ``--port N``'s
N, N+1 ... in the order the tool asks for them, a taken one named in one line."""

from __future__ import annotations

import argparse
import socket
from collections.abc import Iterator

import pytest

from common.contracts import ControllerMode
from common.errors import ConfigError
from simworld.scenarios import SCENARIOS
from stack.config import Config
from tools.ports import add_port, free_port, private_endpoint, use_ports
from tools.scenarios.robots import robots_plan
from tools.scenarios.runner import scenario_config


@pytest.fixture(autouse=True)
def no_plan_after() -> Iterator[None]:
    yield
    use_ports(None)  # the plan is the process's: leave the default for the next test


def free_block(n: int) -> int:
    """The first of ``n`` consecutive ports that are free on 127.0.0.1 now."""
    for _ in range(50):
        first = free_port()
        if first + n > 65536:
            continue
        try:
            for port in range(first, first + n):
                with socket.socket() as s:
                    s.bind(("127.0.0.1", port))
        except OSError:
            continue
        return first
    raise AssertionError(f"no {n} free ports in a row")


def port_of(endpoint: str) -> int:
    return int(endpoint.rsplit(":", 1)[1])


def test_without_a_plan_each_endpoint_is_a_free_port_of_the_system() -> None:
    a, b = private_endpoint(), private_endpoint()
    assert a.startswith("tcp/127.0.0.1:") and a != b


def test_a_scenario_run_listens_on_the_given_port_and_its_ros2_router_on_the_next() -> None:
    first = free_block(2)
    use_ports(first)
    config = scenario_config(Config(), SCENARIOS["ahead"], ros2=True)
    assert config.zenoh.endpoint == f"tcp/127.0.0.1:{first}"
    assert config.ros2.router == (f"tcp/127.0.0.1:{first + 1}",)


def test_several_robots_take_the_ports_in_turn_the_pool_first() -> None:
    first = free_block(3)
    use_ports(first)
    plan = robots_plan(Config(), "ahead", robots=2, workers=1, mode=ControllerMode.FOLLOW)
    assert port_of(plan.pool.zenoh.endpoint) == first
    assert [port_of(r.zenoh.endpoint) for r in plan.robots] == [first + 1, first + 2]


def test_a_taken_port_is_one_line_naming_it_and_the_flag() -> None:
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        taken = holder.getsockname()[1]
        use_ports(taken)
        with pytest.raises(ConfigError, match=rf"--port: port {taken} on 127.0.0.1 is taken"):
            private_endpoint()


def test_the_flag_takes_a_port_number_only() -> None:
    p = argparse.ArgumentParser(exit_on_error=False)
    add_port(p)
    assert p.parse_args([]).port is None
    assert p.parse_args(["--port", "17000"]).port == 17000
    for bad in ("0", "70000", "x"):
        with pytest.raises(argparse.ArgumentError):
            p.parse_args(["--port", bad])
