"""The package layout: dependencies point one way, no import circles, the public surface imports,
and the old import paths still work (with a DeprecationWarning) for one release.

The import graph is read from the source with ``ast`` (no import side effects): every ``import``
and ``from … import`` of an ``optplan`` module, at module level and inside functions (a lazy import
is still a dependency).
"""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest
from import_graph import cycles as _cycles

PKG = Path(__file__).resolve().parents[1] / "optplan"

#: layer of each part of the package; a module may import its own layer and the ones below.
#: Order: geometry → model → constraints / collision / scene → problem / planners → tasks, trials,
#: verification, viz → pipeline → paper reproductions → benchmarks → command line. The package
#: ``optplan/__init__`` (lazy public names) counts as the top; importing it is no dependency.
LAYERS = [
    (0, ("optplan.errors", "optplan.limits", "optplan._compat", "optplan.geometry", "optplan._io", "optplan.cache",
         "optplan.interrupt")),   # files written atomically, the kernel cache's entries, interruption
    (1, ("optplan.codegen", "optplan.solver_options", "optplan.workers", "optplan.model")),
    (2, ("optplan.constraints", "optplan.collision", "optplan.scene")),
    (3, ("optplan.problem", "optplan.planners")),
    (4, ("optplan.tasks", "optplan.trials", "optplan.verification", "optplan.viz", "optplan.shortcuts",
         "optplan.segment_nlp", "optplan.floating_manoeuvre")),   # a kept manoeuvre: a motion verify reads
    (5, ("optplan.pipeline", "optplan.pipeline_options", "optplan.pipeline_workers", "optplan.floating_pipeline")),
    (6, ("optplan.papers",)),
    (7, ("optplan.bench", "optplan.cli_args")),   # cli_args: argument checks shared with the bench commands
    (8, ("optplan.cli", "optplan.cli_bench", "optplan.cli_plan", "optplan._entry", "optplan.reproduce", "optplan.demo", "optplan")),
]


def _layer(module: str) -> int:
    best, rank = "", None
    for r, prefixes in LAYERS:
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > len(best):
                best, rank = p, r
    assert rank is not None, f"{module}: no layer (add it to LAYERS in {__file__})"
    return rank


def _modules() -> dict[str, tuple[Path, bool]]:
    out = {}
    for p in sorted(PKG.rglob("*.py")):
        parts = list(p.relative_to(PKG.parent).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        if is_pkg:
            parts = parts[:-1]
        out[".".join(parts)] = (p, is_pkg)
    return out


def _imports(module: str, path: Path, is_pkg: bool, known) -> list[tuple[str, int, bool]]:
    """``(imported optplan module, line, inside a function)`` of one file (imports under
    ``if TYPE_CHECKING:`` are left out: they do not run)."""
    found = []

    def targets(node):
        if isinstance(node, ast.Import):
            return [a.name for a in node.names if a.name.split(".")[0] == "optplan"]
        if node.level:
            pkg = module.split(".") if is_pkg else module.split(".")[:-1]
            base = ".".join(pkg[:len(pkg) - node.level + 1] + ([node.module] if node.module else []))
        else:
            base = node.module or ""
        if base.split(".")[0] != "optplan":
            return []
        return [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue  # type-only imports: no import at run time (annotations are strings)
            f = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                found.extend((t, child.lineno, f) for t in targets(child))
            visit(child, f)

    visit(ast.parse(path.read_text()), False)
    return found


@pytest.fixture(scope="module")
def graph():
    mods = _modules()
    return mods, {m: _imports(m, p, is_pkg, mods) for m, (p, is_pkg) in mods.items()}


def test_every_module_has_a_layer(graph):
    mods, _ = graph
    for m in mods:
        _layer(m)


def test_no_upward_imports(graph):
    """geometry never imports model, the library never imports papers/ or bench/, ..."""
    _, edges = graph
    bad = []
    for m, imps in edges.items():
        for t, line, _ in imps:
            if t != "optplan" and _layer(t) > _layer(m):
                bad.append(f"{m}:{line} imports {t} (layer {_layer(m)} -> {_layer(t)})")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_circles(graph):
    """No circles among the package's modules, lazy (function-level) imports included."""
    _, edges = graph
    adj = {m: {t for t, _, _ in imps if t != m and t != "optplan"} for m, imps in edges.items()}
    assert _cycles(adj) == []


def test_papers_and_bench_stay_out_of_the_main_job(graph):
    """The pipeline and the ``plan`` command do not import a paper reproduction or a benchmark."""
    _, edges = graph
    for m in ("optplan.pipeline", "optplan.tasks", "optplan.trials", "optplan.verification"):
        assert not [t for t, _, _ in edges[m] if t.startswith(("optplan.papers", "optplan.bench"))], m
    # the plan command is its own module: none of its imports (lazy ones included) is a paper or a benchmark
    assert not [t for t, _, _ in edges["optplan.cli_plan"] if t.startswith(("optplan.papers", "optplan.bench"))]


# --------------------------------------------------------------------------- public surface
def test_every_public_name_imports():
    import optplan

    assert len(optplan.__all__) == len(set(optplan.__all__))
    for name in optplan.__all__:
        assert getattr(optplan, name) is not None, name
    ns: dict = {}
    exec("from optplan import *", ns)
    assert {n for n in optplan.__all__ if n != "__version__"} <= set(ns)
    assert callable(optplan.verify) and callable(optplan.run_pipeline) and callable(optplan.make_planner)
    from optplan.problem import ClosedChain

    assert optplan.ClosedChain is ClosedChain


def test_import_optplan_stays_cheap():
    """The public names load on first use: ``import optplan`` pulls in no solver or model library."""
    code = ("import sys, optplan; heavy = [m for m in ('casadi', 'pinocchio', 'coal', 'scipy', 'matplotlib') "
            "if m in sys.modules]; print(heavy)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "[]"


_OLD_PATHS_SCRIPT = r"""
import importlib, json, sys, warnings
import optplan
from optplan._compat import MOVED_MODULES

out = {"modules": {}, "names": {}}
# the forms users wrote
with warnings.catch_warnings(record=True) as w:
    warnings.simplefilter("always")
    from optplan.robot import RobotModel as R1
    from optplan.methods.eba import run_eba as e1
    from optplan.warmstart import manifold_resample as m1
    sp = optplan.spatial   # attribute access to an old submodule after ``import optplan``
out["from_import"] = [sp is importlib.import_module("optplan.geometry.spatial"), R1 is optplan.RobotModel,
                      e1 is importlib.import_module("optplan.papers.eba").run_eba,
                      m1 is importlib.import_module("optplan.constraints.closed_chain").manifold_resample,
                      sum(issubclass(x.category, DeprecationWarning) for x in w) >= 4]
for old, new in MOVED_MODULES.items():
    sys.modules.pop(old, None)   # imported above through the old path: import it again
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        m = importlib.import_module(old)
    out["modules"][old] = [m is importlib.import_module(new),
                           any(issubclass(x.category, DeprecationWarning) and new in str(x.message) for x in w)]
# names that moved out of modules that stay
for old_mod, name, new_mod in [
        ("optplan.problem.terms", "ClosedChain", "optplan.problem.frame_terms"),
        ("optplan.model.description", "urdf_string", "optplan.model.urdf_writer"),
        ("optplan.model.ik", "solve_grasp_ik", "optplan.constraints.closed_chain"),
        ("optplan.papers.dshdasr.arcs", "DiscreteArcModel", "optplan.papers.dshdasr.arc_models"),
        ("optplan.planners", "ClosedChainKinematics", "optplan.constraints.closed_chain"),
        ("optplan.planners", "interpolate_task", "optplan.planners.tcbirrt")]:
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        obj = getattr(importlib.import_module(old_mod), name)
    out["names"][f"{old_mod}.{name}"] = [obj is getattr(importlib.import_module(new_mod), name),
                                         any(issubclass(x.category, DeprecationWarning) for x in w)]
print(json.dumps(out))
"""


def test_old_import_paths_warn_and_resolve_to_the_same_objects():
    """Run in a fresh interpreter: importing an old path rebinds ``optplan.<old name>`` to the module."""
    r = subprocess.run([sys.executable, "-c", _OLD_PATHS_SCRIPT], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["modules"] and all(same for same, _ in out["modules"].values()), out["modules"]
    assert all(warned for _, warned in out["modules"].values()), out["modules"]
    assert all(same and warned for same, warned in out["names"].values()), out["names"]
    assert all(out["from_import"]), out["from_import"]


def test_the_library_imports_no_old_path(graph):
    """Inside the package every import uses the new paths (an old one would warn on every use)."""
    from optplan._compat import MOVED_MODULES

    _, edges = graph
    bad = [f"{m}:{line} imports {t}" for m, imps in edges.items() for t, line, _ in imps
           if any(t == old or t.startswith(old + ".") for old in MOVED_MODULES)]
    assert not bad, bad


# --------------------------------------------------------------------------- paper keys
def test_paper_keys_name_the_reproductions(tmp_path):
    """The keys of docs/papers.md: a package per reproduction, and ``optplan reproduce`` takes the
    key with an underscore as well as the command-line hyphen."""
    from optplan.reproduce import PAPERS, plan_steps

    assert {k.replace("-", "_") for k in PAPERS} == {"tcbirrt", "eba", "dshdasr", "spline_rrt", "oc_rrt"}
    for key in ("eba", "dshdasr", "spline_rrt"):
        assert (PKG / "papers" / key / "__init__.py").exists()
    assert [s.argv for s in plan_steps("spline_rrt", tmp_path, quick=True)] == \
           [s.argv for s in plan_steps("spline-rrt", tmp_path, quick=True)]
    text = (PKG.parent / "docs" / "papers.md").read_text()
    for key in ("tcbirrt", "spline_rrt", "oc_rrt", "dshdasr", "eba"):
        assert f"| `{key}` |" in text
