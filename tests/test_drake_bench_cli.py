"""`optplan bench drake` argument errors: a clear message and exit status 2 before any solve,
with or without Drake installed."""
from __future__ import annotations

import sys

import pytest

from optplan import cli


@pytest.mark.parametrize("argv, message", [
    (["--segments", "flying"], "--segments"),
    (["--problems", "nowhere"], "unknown problem"),
    (["--solvers", "gurobi"], "solver"),
])
def test_bad_arguments_are_errors(capsys, argv, message):
    rc = cli.main(["bench", "drake", *argv])
    assert rc == 2
    assert message in capsys.readouterr().err


def test_missing_drake_names_the_extra(capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "pydrake", None)  # `import pydrake` raises ImportError, as when absent
    rc = cli.main(["bench", "drake", "--problems", "transport"])
    assert rc == 2 and 'optplan[drake]' in capsys.readouterr().err
