"""Pipeline options reach the planner that is chosen, and success is judged with the tolerance the
user set: ``planner_options`` are passed to any planner (an option it does not have is an
OptionError naming the planner's options), and ``PipelineResult.success`` uses
``closed_chain_tol``."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from optplan.errors import OptionError
from optplan.model.robot import RobotModel
from optplan.pipeline import PLANNER_DEFAULTS, PipelineOptions, PipelineResult, run_pipeline
from optplan.planners import make_planner
from optplan.scene import Scene


@pytest.fixture(scope="module")
def robot_scene():
    return RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("ssps_scene1")


def test_planner_options_default_per_planner_and_explicit_ones_pass_through():
    assert PipelineOptions().planner_kwargs() == dict(PLANNER_DEFAULTS["tcbirrt"])
    assert PipelineOptions(planner="cbirrt2").planner_kwargs() == {}
    assert PipelineOptions(planner="rrtconnect", planner_options=(("range", 0.5),)).planner_kwargs() == \
        {"range": 0.5}


def test_make_planner_names_the_unknown_option_and_the_known_ones(robot_scene):
    robot, scene = robot_scene
    with pytest.raises(OptionError, match=r"cbirrt2.*variant.*CBiRRT2Options has:"):
        make_planner("cbirrt2", robot, scene, variant="improved")


def test_run_pipeline_no_longer_drops_options_of_other_planners(robot_scene):
    """Before, any option given for a planner other than TCBiRRT was silently ignored."""
    robot, scene = robot_scene
    q = robot.neutral()
    with pytest.raises(OptionError, match="not_an_option"):
        run_pipeline(robot, scene, q, q, PipelineOptions(planner="cbirrt2", planner_options=(("not_an_option", 1),)))


def _result(residual: float, tol: float) -> PipelineResult:
    seg = SimpleNamespace(kind="constrained", solution=SimpleNamespace(success=True),
                          report=SimpleNamespace(max_closed_chain_residual=residual, min_clearance_m=0.01))
    return PipelineResult(plan=SimpleNamespace(success=True), segments=[seg], closed_chain_tol=tol)


def test_success_uses_the_closed_chain_tolerance():
    assert _result(5e-6, 1e-5).success          # was judged against a hard-coded 1e-6
    assert not _result(5e-6, 1e-6).success
    assert not _result(5e-7, 1e-7).success
    assert _result(5e-7, 1e-6).success


@pytest.mark.parametrize("bad", [0, -3, 2.5, "200"])
def test_spline_max_iterations_is_checked(bad):
    from optplan.pipeline import PipelineOptions

    with pytest.raises(ValueError, match="spline_max_iterations"):
        PipelineOptions(spline_max_iterations=bad)


@pytest.mark.parametrize("name", ["ipopt_options", "globalization_retry_options"])
@pytest.mark.parametrize("bad", [{"max_iter": 5}, (("max_iter",),), ((5, "x"),), "max_iter=5"])
def test_ipopt_option_pairs_are_checked(name, bad):
    with pytest.raises(OptionError, match=name):
        PipelineOptions(**{name: bad})


@pytest.mark.parametrize("name", ["ipopt_options", "globalization_retry_options"])
@pytest.mark.parametrize("pair, says", [(("linear_solvr", "mumps"), "unknown IPOPT"),
                                        (("mu_strategy", "fast"), "refused by IPOPT"),
                                        (("tol", -1.0), "refused by IPOPT")])
def test_ipopt_option_names_and_values_are_checked_by_ipopt_when_the_options_are_made(name, pair, says):
    """A misspelt option or a refused value is a clear error before any planning, not a status of
    every segment's solve."""
    with pytest.raises(OptionError, match=f"PipelineOptions.{name}.*{pair[0]}.*{says}"):
        PipelineOptions(**{name: (pair,)})
    assert PipelineOptions(**{name: (("tol", 1e-7),)})   # a value IPOPT takes


def test_a_linear_solver_ipopt_cannot_load_is_named_when_the_options_are_made():
    """IPOPT accepts any linear solver's name and fails at the first solve when its library (HSL's,
    Pardiso's) is missing, with an unset iteration counter: the options say so instead."""
    from optplan.problem.nlp import IpoptStatus, outcome_from_stats
    from optplan.solver_options import check_ipopt_options

    with pytest.raises(OptionError, match="linear_solver.*ma27.*cannot load"):
        PipelineOptions(ipopt_options=(("linear_solver", "ma27"),))
    with pytest.raises(OptionError, match="ma57.*cannot load"):
        check_ipopt_options({"linear_solver": "ma57", "hsllib": "/nonexistent/libhsl.so"})
    check_ipopt_options({"linear_solver": "mumps"})   # always available
    bad = outcome_from_stats({"return_status": "Invalid_Option", "iter_count": 10878976}, None, wall_time=0.0)
    assert bad.status is IpoptStatus.INVALID_OPTION and bad.iterations == 0


def test_the_segments_use_never_monotone_mu_and_retry_with_the_filter():
    opts = PipelineOptions()
    assert dict(opts.ipopt_options)["adaptive_mu_globalization"] == "never-monotone-mode"
    assert dict(opts.globalization_retry_options) == {"adaptive_mu_globalization": "obj-constr-filter"}
    assert PipelineOptions(globalization_retry_options=()).globalization_retry_options == ()


def test_early_worker_takes_a_bool_or_none():
    from optplan.errors import OptionError

    for ok in (None, True, False):
        PipelineOptions(early_worker=ok)
    with pytest.raises(OptionError, match="early_worker.*'yes'"):
        PipelineOptions(early_worker="yes")


def test_first_grid_of_a_segment_follows_its_length_up_to_its_cap():
    """⌈length / step⌉ intervals between ``spline_min_intervals`` and the first grid's cap (itself within
    ``spline_max_intervals``); a regrasp steps by ``free_interval_step``."""
    o = PipelineOptions()
    assert (o.spline_interval_step, o.spline_min_intervals, o.spline_first_max_intervals) == (0.05, 30, 100)
    assert o.spline_intervals(0.2, "constrained") == 30                 # short: the floor
    assert o.spline_intervals(3.01, "constrained") == 61                # ⌈3.01 / 0.05⌉
    assert o.spline_intervals(6.73, "constrained") == 100               # scene 1's long segment: 135 → the cap
    assert o.spline_intervals(6.73, "regrasp") == 45                    # ⌈6.73 / 0.15⌉
    assert PipelineOptions(spline_first_max_intervals=160).spline_intervals(6.73, "constrained") == 135
    assert PipelineOptions(spline_max_intervals=60).spline_intervals(6.73, "constrained") == 60
    assert PipelineOptions(spline_min_intervals=120, spline_max_intervals=160).spline_intervals(1.0, "constrained") == 120
    for bad in (3, 2.5, True, "100"):
        with pytest.raises(OptionError, match="spline_first_max_intervals.*" + repr(bad).replace("(", r"\(")):
            PipelineOptions(spline_first_max_intervals=bad)


def test_options_are_checked_together_and_a_refused_one_is_still_named(monkeypatch):
    """Options IPOPT has not taken before in this process are tried in one instance (the pipeline's
    ~13 per segment: one IPOPT creation, not 13); when IPOPT refuses the set, each is tried alone and
    the one it refuses is named."""
    import casadi as ca

    import optplan.solver_options as so

    monkeypatch.setattr(so, "_ACCEPTED", set())
    made = []
    real = ca.nlpsol

    def counting(*a, **k):
        made.append(a[3] if len(a) > 3 else k.get("opts"))
        return real(*a, **k)

    monkeypatch.setattr(ca, "nlpsol", counting)
    good = {"tol": 1.25e-7, "max_iter": 321, "mu_strategy": "adaptive", "acceptable_iter": 7}
    so.check_ipopt_options(good)
    assert len(made) == 1 and all(f"ipopt.{k}" in made[0] for k in good)
    so.check_ipopt_options(good)   # accepted before: nothing made
    assert len(made) == 1
    with pytest.raises(OptionError, match=r"ipopt_options\['acceptable_tol'\] = -2.0: refused"):
        so.check_ipopt_options({"tol": 1.5e-7, "acceptable_tol": -2.0, "max_iter": 99})
