"""zstack: one command line, each command the module that owns it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from deploy.zstack import COMMANDS, resolve

REPO = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize(
    "argv, module, args",
    [
        (["run", "--duration", "5"], "deploy.supervisor", ["--duration", "5"]),
        (
            ["serve", "camera", "--config", "x.toml"],
            "services.camera",
            ["serve", "--config", "x.toml"],
        ),
        (["detect", "a.jpg", "--json"], "tools.detector", ["detect", "a.jpg", "--json"]),
        (["fetch-model"], "tools.detector", ["fetch-model"]),
        (["prepare", "--config", "x.toml"], "tools.detector", ["prepare", "--config", "x.toml"]),
        (["query"], "services.metrics", ["query"]),
        (["scenario", "ahead"], "tools.scenarios", ["scenario", "ahead"]),
        (["scenarios"], "tools.scenarios", ["list"]),
        (["estop", "engage"], "services.controller", ["estop", "engage"]),
        (["credentials", "--force"], "deploy.credentials", ["--force"]),
        (["viewer-layout", "--out", "l.json"], "services.viewer", ["layout", "--out", "l.json"]),
        (
            ["scale-benchmark", "--cameras", "1,2"],
            "tools.benchmarks",
            ["scale", "--cameras", "1,2"],
        ),
    ],
)
def test_each_command_runs_its_module(argv: list[str], module: str, args: list[str]) -> None:
    assert resolve(argv) == (module, args)


def test_every_task_of_the_issue_has_a_command() -> None:
    tasks = {"run", "detect", "benchmark", "query", "evaluate", "report", "scenario", "estop",
             "fetch-model", "prepare"}  # fmt: skip
    assert tasks <= COMMANDS.keys()


@pytest.mark.parametrize("argv", [["dance"], ["serve"], ["serve", "toaster"], []])
def test_unknown_commands_exit_2(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as done:
        resolve(argv)
    assert done.value.code == 2


def test_the_console_script_and_the_module_agree() -> None:
    script = Path(sys.executable).parent / "zstack"
    for cmd in ([str(script)], [sys.executable, "-m", "deploy.zstack"]):
        done = subprocess.run(
            [*cmd, "scenarios"], cwd=REPO, capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 0, done.stderr
        assert done.stdout.splitlines()[0].startswith("demo")
