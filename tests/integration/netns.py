"""Network namespaces for the tests that play several hosts (test_two_hosts.py,
test_readme_pool.py): iproute2's ``ip``, run as root."""

from __future__ import annotations

import subprocess


def ip(*args: str) -> None:
    """Run ``ip args``; RuntimeError with its stderr when it fails."""
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {done.stderr.strip()}")
