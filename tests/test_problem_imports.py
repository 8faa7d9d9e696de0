"""``optplan/problem/`` has no import cycle: the modules' imports of each other, read with
``ast`` — at module level, including those under ``if TYPE_CHECKING:`` (a cycle there is still a
cycle of the design; imports inside functions are deferred and not counted)."""
from __future__ import annotations

import ast
from pathlib import Path

from import_graph import cycles

import optplan.problem

PACKAGE = Path(optplan.problem.__file__).parent


def imports_of(source: str, modules: set[str], name: str) -> set[str]:
    """The sibling modules (of ``modules``) that ``source`` imports outside functions."""
    out: set[str] = set()

    def visit(nodes: list[ast.stmt]) -> None:
        for n in nodes:
            if isinstance(n, ast.ImportFrom):
                if n.level == 1:
                    out.update([n.module.split(".")[0]] if n.module else [a.name for a in n.names])
                elif n.level == 0 and n.module and n.module.startswith("optplan.problem"):
                    parts = n.module.split(".")
                    out.update([parts[2]] if len(parts) > 2 else [a.name for a in n.names])
            elif isinstance(n, ast.Import):
                out.update(a.name.split(".")[2] for a in n.names if a.name.startswith("optplan.problem."))
            elif isinstance(n, ast.If):          # TYPE_CHECKING blocks and other conditionals
                visit(n.body)
                visit(n.orelse)
            elif isinstance(n, ast.Try):
                visit(n.body)
                visit(n.orelse)
                visit(n.finalbody)
                for h in n.handlers:
                    visit(h.body)

    visit(ast.parse(source).body)
    return {m for m in out if m in modules and m != name}


def _graph() -> dict[str, set[str]]:
    files = {p.stem: p for p in PACKAGE.glob("*.py")}
    return {m: imports_of(p.read_text(), set(files), m) for m, p in files.items()}


def test_the_reader_sees_type_checking_imports_and_the_finder_sees_a_cycle():
    src = "from typing import TYPE_CHECKING\nfrom .b import X\nif TYPE_CHECKING:\n    from .c import Y\n" \
          "def f():\n    from .d import Z\n"
    assert imports_of(src, {"a", "b", "c", "d"}, "a") == {"b", "c"}
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    g = _graph()
    assert "guarantees" in g["problem"] and "terms" in g["handles"]   # real edges are read


def test_optplan_problem_has_no_import_cycle():
    found = cycles(_graph())
    assert not found, f"import cycles in optplan/problem (module level, TYPE_CHECKING included): {found}"
