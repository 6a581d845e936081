"""The error tree in common/errors.py's docstring draws every StackError subclass in the project,
each under its own base; classes are found with ``ast``, so nothing has to be imported."""

from __future__ import annotations

import ast
import re

import common.errors
from tests.unit.packages import PACKAGES, ROOT


def stack_errors() -> dict[str, str]:
    """Every public subclass of StackError in the packages -> the name of its base.

    A private one (``_Name``: a detail of one module) is not drawn."""
    bases: dict[str, list[str]] = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.ClassDef):
                    names = [b.attr if isinstance(b, ast.Attribute) else ast.unparse(b)
                             for b in node.bases]  # fmt: skip
                    bases.setdefault(node.name, []).extend(names)
    found = {"StackError": ""}
    grew = True
    while grew:
        grew = False
        for name, its in bases.items():
            known = [b for b in its if b in found]
            if name not in found and known:
                found[name] = known[0]
                grew = True
    return {n: b for n, b in found.items() if not n.startswith("_")}


def drawn_tree(doc: str) -> dict[str, str]:
    """The docstring's tree: each class -> its parent (the root's is "")."""
    tree: dict[str, str] = {}
    stack: list[str] = []
    for line in doc.splitlines():
        if m := re.match(r"^ {4}((?:│   |    )*)(?:├── |└── )(\w+)", line):
            depth = len(m.group(1)) // 4 + 1
        elif m := re.match(r"^ {4}()(StackError)\b", line):
            depth = 0
        else:
            continue
        del stack[depth:]
        tree[m.group(2)] = stack[-1] if stack else ""
        stack.append(m.group(2))
    return tree


def test_the_docstring_draws_every_stack_error_under_its_base() -> None:
    assert common.errors.__doc__ is not None
    assert drawn_tree(common.errors.__doc__) == stack_errors()


def test_the_tree_reader_sees_depth() -> None:
    doc = "    StackError  x\n    ├── A  a\n    │   └── B  b\n    │       more\n    └── C  c\n"
    assert drawn_tree(doc) == {"StackError": "", "A": "StackError", "B": "A", "C": "StackError"}
