"""common/clock.py is the only production module that reads a clock, read with ``ast``.

A clock read is any use of the ``time`` module's clocks (``time.monotonic()``, or
``time.monotonic`` passed as a default), ``from time import monotonic``, and ``now``,
``utcnow`` or ``today`` on ``datetime.datetime`` or ``datetime.date``. ``time.sleep`` reads
no clock and is not counted.
"""

from __future__ import annotations

import ast

from tests.unit.packages import PACKAGES, ROOT

CLOCK_MODULE = ROOT / "common" / "clock.py"

#: The ``time`` functions that read a clock (the formatting ones read it when given no time).
TIME_CLOCKS = frozenset(
    {
        "time", "time_ns", "monotonic", "monotonic_ns", "perf_counter", "perf_counter_ns",
        "process_time", "process_time_ns", "thread_time", "thread_time_ns", "clock_gettime",
        "clock_gettime_ns", "localtime", "gmtime", "ctime", "asctime", "strftime",
    }
)  # fmt: skip
DATETIME_CLOCKS = frozenset({"now", "utcnow", "today"})
DATETIME_CLASSES = frozenset({"datetime", "date"})


def clock_reads(source: str) -> list[str]:
    """``line: what`` for each clock read in ``source``."""
    tree = ast.parse(source)
    time_modules, datetime_modules, datetime_classes = set(), set(), set()
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == "time":
                    time_modules.add(alias.asname or "time")
                elif alias.name == "datetime":
                    datetime_modules.add(alias.asname or "datetime")
        elif isinstance(node, ast.ImportFrom) and node.module in ("time", "datetime"):
            for alias in node.names:
                if node.module == "time" and alias.name in TIME_CLOCKS:
                    found.append(f"{node.lineno}: from time import {alias.name}")
                elif node.module == "datetime" and alias.name in DATETIME_CLASSES:
                    datetime_classes.add(alias.asname or alias.name)
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        owner = node.value
        if isinstance(owner, ast.Name) and owner.id in time_modules and node.attr in TIME_CLOCKS:
            found.append(f"{node.lineno}: {owner.id}.{node.attr}")
        elif node.attr in DATETIME_CLOCKS and (
            (isinstance(owner, ast.Name) and owner.id in datetime_classes)
            or (
                isinstance(owner, ast.Attribute)
                and owner.attr in DATETIME_CLASSES
                and isinstance(owner.value, ast.Name)
                and owner.value.id in datetime_modules
            )
        ):
            found.append(f"{node.lineno}: {ast.unparse(owner)}.{node.attr}")
    return sorted(found, key=lambda f: int(f.split(":")[0]))


def test_no_production_module_but_common_clock_reads_a_clock() -> None:
    wrong = [
        f"{path.relative_to(ROOT)}:{read}"
        for pkg in PACKAGES
        for path in sorted((ROOT / pkg).rglob("*.py"))
        if path != CLOCK_MODULE
        for read in clock_reads(path.read_text(encoding="utf-8"))
    ]
    assert wrong == [], "read the clock through common/clock.py:\n" + "\n".join(wrong)


def test_the_rule_sees_each_way_of_reading_a_clock() -> None:
    source = (
        "import time\n"
        "import time as t\n"
        "import datetime\n"
        "from datetime import datetime as dt, date\n"
        "from time import perf_counter\n"
        "a = time.monotonic()\n"
        "def f(clock=t.monotonic): ...\n"
        "b = datetime.datetime.now(datetime.UTC)\n"
        "c = dt.now()\n"
        "d = date.today()\n"
        "time.sleep(0.1)\n"
        "e = dt.fromisoformat('2024-01-01')\n"
    )
    assert clock_reads(source) == [
        "5: from time import perf_counter",
        "6: time.monotonic",
        "7: t.monotonic",
        "8: datetime.datetime.now",
        "9: dt.now",
        "10: date.today",
    ]


def test_the_clock_module_itself_reads_the_clocks() -> None:
    assert clock_reads(CLOCK_MODULE.read_text(encoding="utf-8"))  # the rule looks where it should
