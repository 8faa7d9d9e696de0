"""Every public options dataclass documents each field above it (``#: text [unit].``) or in a
docstring right below it, and every numeric field names its unit in brackets (``[m]``, ``[rad]``,
``[s]``, ``[count]``, ``[-]`` for a dimensionless number).

The classes are found in the package's source (a frozen or plain ``@dataclass`` whose name ends in
``Options``, ``Settings`` or ``Config``, in a public module), so a new options class is checked as
soon as it exists.
"""
from __future__ import annotations

import ast
import pathlib
import re

import pytest

import optplan

ROOT = pathlib.Path(optplan.__file__).parent
NAME = re.compile(r"^[A-Z]\w*(Options|Settings|Config)$")
UNIT = re.compile(r"\[[^\]]+\]")
UNITLESS = {"seed"}   # an RNG seed is a number without a unit
NUMERIC = re.compile(r"^(int|float)( \| None)?$|^(None \| )(int|float)$|^float \| str$")


def _is_dataclass(node: ast.ClassDef) -> bool:
    for d in node.decorator_list:
        f = d.func if isinstance(d, ast.Call) else d
        if (isinstance(f, ast.Name) and f.id == "dataclass") or (isinstance(f, ast.Attribute) and f.attr == "dataclass"):
            return True
    return False


def _options_classes():
    out = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if any(part.startswith("_") and part != "__init__.py" for part in rel.parts):
            continue
        src = path.read_text(encoding="utf-8")
        for node in ast.parse(src).body:
            if isinstance(node, ast.ClassDef) and NAME.match(node.name) and _is_dataclass(node):
                out.append((f"{rel.with_suffix('').as_posix().replace('/', '.')}.{node.name}", node, src.splitlines()))
    return out


CLASSES = _options_classes()


def _field_docs(node: ast.ClassDef, lines: list[str]):
    """(field name, annotation, documentation text or None) of each field of the class."""
    body = node.body
    for i, st in enumerate(body):
        if not (isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name)):
            continue
        if ast.unparse(st.annotation).startswith("ClassVar"):
            continue
        comment, k = [], st.lineno - 2
        while k >= 0 and lines[k].strip().startswith("#:"):
            comment.insert(0, lines[k].strip()[2:].strip())
            k -= 1
        nxt = body[i + 1] if i + 1 < len(body) else None
        if isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant) and isinstance(nxt.value.value, str):
            comment.append(nxt.value.value.strip())
        yield st.target.id, ast.unparse(st.annotation), " ".join(comment) or None


def test_the_public_options_classes_are_found():
    names = {q.rsplit(".", 1)[1] for q, _, _ in CLASSES}
    for expected in ("PipelineOptions", "SolverOptions", "TCBiRRTOptions", "CBiRRT2Options", "RRTConnectOptions",
                     "OCRRTOptions", "OMPLPeerOptions", "CoordinatedRRTStarOptions", "IKSettings", "TrialOptions",
                     "BenchConfig", "WarmstartConfig", "DrakeOptions"):
        assert expected in names, f"{expected} not found among {sorted(names)}"


@pytest.mark.parametrize("qualname,node,lines", CLASSES, ids=[c[0] for c in CLASSES])
def test_every_field_is_documented_with_its_unit(qualname, node, lines):
    missing, no_unit = [], []
    for name, annotation, doc in _field_docs(node, lines):
        if doc is None:
            missing.append(name)
        elif NUMERIC.match(annotation) and name not in UNITLESS and not UNIT.search(doc):
            no_unit.append(f"{name}: {doc!r}")
    assert not missing, f"{qualname}: fields without a '#:' line above them: {missing}"
    assert not no_unit, f"{qualname}: numeric fields whose documentation names no unit in brackets: {no_unit}"


def test_the_checker_sees_an_undocumented_field():
    src = "@dataclass(frozen=True)\nclass FooOptions:\n    #: Step [m].\n    a: float = 1.0\n    b: int = 2\n    c: float = 0.5\n    '''Rate.'''\n"
    node = ast.parse(src).body[0]
    docs = {n: (a, d) for n, a, d in _field_docs(node, src.splitlines())}
    assert docs["a"] == ("float", "Step [m].") and docs["b"][1] is None and docs["c"][1] == "Rate."
    assert NUMERIC.match(docs["c"][0]) and not UNIT.search(docs["c"][1])
