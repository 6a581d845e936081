from __future__ import annotations

import os
from pathlib import Path

import pytest

from common.errors import ConfigError
from deploy.lock import acquire


def test_second_holder_is_refused_naming_the_first(tmp_path: Path) -> None:
    first = acquire(str(tmp_path), "tcp/127.0.0.1:7447", "stack")
    try:
        with pytest.raises(ConfigError, match=rf"pid {os.getpid()}\b.*already runs"):
            acquire(str(tmp_path), "tcp/127.0.0.1:7447", "stack")
        # Another prefix or endpoint is another stack.
        acquire(str(tmp_path), "tcp/127.0.0.1:7447", "other").close()
        acquire(str(tmp_path), "tcp/127.0.0.1:7448", "stack").close()
    finally:
        first.close()
    acquire(str(tmp_path), "tcp/127.0.0.1:7447", "stack").close()  # free again
