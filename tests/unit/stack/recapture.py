"""Capture the access rules again into data/access_before.json, for each case it holds:
``python -m tests.unit.stack.recapture``. Only after a deliberate change of what a contract
declares (say so in the commit): test_access.py then holds the new rules as the reference."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from common.keys import Keys
from common.security import stack_principals
from stack.access import access_control
from stack.access_table import congestion_overwritten, may_announce, may_put, may_read

CAPTURE = Path(__file__).parent / "data" / "access_before.json"


FIELDS = {"keys", "cameras", "auth", "workers", "live_sensors"}


def capture(case: dict[str, Any]) -> dict[str, Any]:
    unknown = set(case) - FIELDS
    if unknown:  # a case test_access.py reads more of than this script passes on
        raise SystemExit(f"recapture: case fields {sorted(unknown)} are not passed on; add them")
    keys, cameras = Keys(case["keys"]), case["cameras"]
    workers = tuple(case.get("workers", ("detector",)))
    live = case.get("live_sensors", True)
    principals = stack_principals(cameras, workers)
    return {
        "case": case,
        "access_control": access_control(
            keys, cameras, case["auth"], live_sensors=live, workers=workers
        ),
        "may_put": {
            p: list(may_put(keys, cameras, p, live_sensors=live, workers=workers))
            for p in principals
        },
        "may_announce": {
            p: list(may_announce(keys, cameras, p, workers=workers)) for p in principals
        },
        "may_read": {p: list(may_read(keys, cameras, p)) for p in principals},
        "congestion_overwritten": list(congestion_overwritten(keys, cameras, workers=workers)),
    }


def main() -> None:
    before = json.loads(CAPTURE.read_text())
    CAPTURE.write_text(json.dumps({n: capture(c["case"]) for n, c in before.items()}, indent=1))


if __name__ == "__main__":
    main()
