"""Find the processes the supervisor started for one stack config (Linux /proc)."""

from __future__ import annotations

from pathlib import Path


def service_pids(service: str, config_path: str | Path) -> list[int]:
    """PIDs of ``python -m services.<service> ... --config <config_path>``."""
    want = (f"services.{service}".encode(), str(config_path).encode())
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue  # the process ended while we looked
        if all(w in argv for w in want):
            pids.append(int(entry.name))
    return pids
