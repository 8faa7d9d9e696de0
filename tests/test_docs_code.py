"""The code on the documentation pages that teach extending optplan runs: every ```python block of a
page is executed, in order, in one namespace per page (a page is a tutorial read top to bottom)."""
from __future__ import annotations

import pathlib
import re
import sys
import types

import pytest

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"
PAGES = ["add_a_term.md", "add_a_planner.md", "architecture.md", "tutorials/own-problem.md"]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks(text: str) -> list[str]:
    return BLOCK.findall(text)


def test_block_extraction():
    text = "intro\n```python\nx = 1\n```\n```bash\nls\n```\n```python\ny = x + 1\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = x + 1\n"]


@pytest.mark.parametrize("page", PAGES)
def test_code_blocks_run(page):
    text = (DOCS / page).read_text(encoding="utf-8")
    blocks = python_blocks(text)
    if page != "architecture.md":
        assert blocks, f"{page}: no python code blocks"
    # a module of its own, registered while it runs (dataclasses look their module up in sys.modules)
    module = types.ModuleType("_docs_" + page.removesuffix(".md").replace("/", "_").replace("-", "_"))
    sys.modules[module.__name__] = module
    try:
        for i, code in enumerate(blocks):
            try:
                exec(compile(code, f"docs/{page} [block {i + 1}]", "exec"), module.__dict__)
            except Exception as exc:  # name the page and block, keep the traceback
                raise AssertionError(f"docs/{page}, python block {i + 1} failed: {type(exc).__name__}: {exc}") from exc
    finally:
        del sys.modules[module.__name__]


def test_decision_records_linked_from_the_code_exist():
    """Every ``docs/decisions/NNNN-title.md`` named in the package's source or the docs is a file."""
    root = DOCS.parent
    pattern = re.compile(r"docs/decisions/\d{4}-[a-z0-9-]+\.md")
    named = set()
    for path in list((root / "optplan").rglob("*.py")) + list(DOCS.rglob("*.md")):
        named |= set(pattern.findall(path.read_text(encoding="utf-8")))
    assert named, "no decision record is linked from the code"
    missing = sorted(n for n in named if not (root / n).is_file())
    assert not missing, f"linked decision records that do not exist: {missing}"
