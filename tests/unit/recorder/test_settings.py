"""The [recorder] table: bounds with one-line errors, and where a recording goes."""

from __future__ import annotations

import dataclasses
from datetime import datetime

import pytest

from common.errors import ConfigError
from common.settings import REPO_ROOT
from services.recorder.contract import Compression, RecorderSettings
from services.recorder.service import default_path
from stack.config import Config


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("queue_size", 0, "queue_size must be within 1..100000"),
        ("chunk_size_kb", 8, "chunk_size_kb must be within 16..65536"),
        ("flush_period_s", 0.0, "flush_period_s must be within 0.05..60"),
        ("file_pattern", "run.bag", "must be a file name ending in .mcap"),
        ("file_pattern", "a/b.mcap", "must be a file name ending in .mcap"),
        ("compression", "gzip", "must be one of lz4, zstd, none"),
        ("output_dir", "", "must not be empty"),
        ("progress_period_s", -1.0, "progress_period_s must be within 0.1..3600"),
    ],
)
def test_out_of_range_settings_are_refused(field: str, value: object, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        RecorderSettings(**{field: value})  # type: ignore[arg-type]


def test_the_default_path_fills_in_the_time_under_the_repo() -> None:
    config = Config()
    assert config.recorder.compression is Compression.LZ4
    at = datetime(2026, 11, 23, 4, 5, 6)
    assert default_path(config, at) == REPO_ROOT / "recordings" / "stack-20261123-040506.mcap"
    elsewhere = dataclasses.replace(
        config, recorder=RecorderSettings(output_dir="/data", file_pattern="{time}-x.mcap")
    )
    assert str(default_path(elsewhere, at)) == "/data/20261123-040506-x.mcap"
