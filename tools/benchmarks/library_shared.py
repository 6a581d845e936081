"""What the library comparisons (tools/benchmarks/library_choices.py) share: timing, ratios, the
installed size and requirements of a distribution, cold import time, a file's line count, and
the one-line notice of a library that is not installed."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.clock import perf_s

REPO = Path(__file__).resolve().parents[2]


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def missing(package: str, what: str) -> None:
    print(f"  [skipped] {what}: `pip install {package}` (into a throwaway venv or --target dir)")


def per_call_us(fn: Callable[[], Any], min_s: float = 0.1, repeats: int = 7) -> float:
    """Best of ``repeats`` means of ``fn()`` in microseconds, each run at least ``min_s``."""
    fn()
    best = math.inf
    for _ in range(repeats):
        n, t0 = 0, perf_s()
        while True:
            fn()
            n += 1
            elapsed = perf_s() - t0
            if elapsed >= min_s:
                break
        best = min(best, elapsed / n * 1e6)
    return best


def ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}x" if b > 0 else "-"


def site_size_mb(dist_names: list[str]) -> float | None:
    """Installed size of the given distributions (their RECORD files), in MB."""
    from importlib import metadata

    total = 0
    for name in dist_names:
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            return None
        for f in dist.files or ():
            p = Path(str(dist.locate_file(f)))
            if p.is_file():
                total += p.stat().st_size
    return total / 1e6


def requirements(dist: str) -> list[str]:
    """The distribution's own requirements, extras left out."""
    from importlib import metadata

    reqs = metadata.requires(dist) or []
    return [r.split(";")[0].strip() for r in reqs if "extra ==" not in r]


def cold_import_ms(module: str, repeats: int = 3) -> float:
    """Best wall time of ``import module`` in a fresh interpreter (this sys.path), ms."""
    code = (
        "import sys, time; sys.path[:0] = sys.argv[1].split(':'); t = time.perf_counter(); "
        f"import {module}; print((time.perf_counter() - t) * 1e3)"
    )
    path = os.pathsep.join(p for p in sys.path if p)
    best = math.inf
    for _ in range(repeats):
        out = subprocess.run(
            [sys.executable, "-c", code, path], capture_output=True, text=True, check=True
        )
        best = min(best, float(out.stdout.strip()))
    return best


def code_lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())
