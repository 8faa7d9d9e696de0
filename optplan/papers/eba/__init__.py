"""The EBA paper — base-attitude restoration of a dual-arm free-floating robot.

The paper's methods and optplan's NLP on the ``eba_ffsr`` model, for the paper's two simulations
(Section 4.1 free ends, Section 4.2 end constraints):

==================  =======================================================  ====================
name                method                                                   module
==================  =======================================================  ====================
``quintic``         5th-order polynomial in joint space (Eq. 34)             :mod:`.eba_baselines`
``ba``              bidirectional approach (Eq. 1-7), Q = 8 I                :mod:`.eba_ba`
``eba``             enhanced bidirectional approach (Eq. 8-24 / 25-33)       :mod:`.eba_ba`
``leader_follower`` leader by quintic, follower by velocity-level IK         :mod:`.eba_baselines`
``fourier``         "near-optimal" Fourier rates (Eq. 35), IPOPT             :mod:`.eba_baselines`
``nlp``             optplan's restoration NLP (``OptProblem``), IPOPT        :mod:`.eba_nlp`
==================  =======================================================  ====================

Every method returns a :class:`MethodResult` (joint trajectory as velocity-continuous segments,
run time, the method's own final-attitude prediction); :func:`evaluate` measures it — final base
attitude from the independent simulator :func:`optplan.simulate_base`, joint error, velocity
jumps, closed-chain residual. :func:`run_case` runs a whole section. Options are frozen dataclasses
validated on construction whose defaults are the paper's. See ``docs/eba.md``.

    from optplan.papers import eba
    case = eba.run_case("free_end")
    rpy = {name: rep.final_base_rpy_deg for name, rep in case.reports.items()}  # [deg]
    text = eba.table(case)                                                    # ours vs the paper's
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ...model.robot import RobotModel
from .ba import BAOptions, EBAOptions, run_ba, run_eba
from .baselines import (
    FourierOptions,
    LeaderFollowerOptions,
    QuinticOptions,
    closed_chain_reference,
    run_fourier,
    run_leader_follower,
    run_quintic,
)
from .core import (
    END_CONSTRAINED_THETAF_DEG,
    FREE_END_THETAF_DEG,
    PAPER_FIGURES,
    THETA0_DEG,
    EBAKinematics,
    MethodReport,
    MethodResult,
    Scenario,
    Segment,
    end_constrained_scenario,
    evaluate,
    free_end_scenario,
    integrate_rpy,
    simulate_result,
)
from .nlp import NLPOptions, build_nlp, run_nlp

__all__ = [
    "BAOptions", "EBAOptions", "QuinticOptions", "LeaderFollowerOptions", "FourierOptions", "NLPOptions",
    "run_ba", "run_eba", "run_quintic", "run_leader_follower", "run_fourier", "run_nlp", "build_nlp",
    "closed_chain_reference", "EBAKinematics", "MethodResult", "MethodReport", "Scenario", "Segment",
    "evaluate", "simulate_result", "integrate_rpy", "free_end_scenario", "end_constrained_scenario",
    "THETA0_DEG", "FREE_END_THETAF_DEG", "END_CONSTRAINED_THETAF_DEG", "PAPER_FIGURES", "CASES", "METHODS",
    "CaseResult", "run_method", "run_case", "scenario", "TARGETS", "criteria", "paper_targets", "verdict", "table",
    "case_json",
    "save_trajectories",
]
log = logging.getLogger(__name__)

#: Methods of each case, in the paper's order (``leader_follower`` only with end constraints,
#: ``quintic`` and ``ba`` only with free ends, as in the paper).
CASES = {
    "free_end": ("quintic", "ba", "eba", "fourier", "nlp"),
    "end_constrained": ("leader_follower", "eba", "fourier", "nlp"),
}

METHODS: dict[str, tuple[Callable[..., MethodResult], type]] = {
    "quintic": (run_quintic, QuinticOptions),
    "ba": (run_ba, BAOptions),
    "eba": (run_eba, EBAOptions),
    "leader_follower": (run_leader_follower, LeaderFollowerOptions),
    "fourier": (run_fourier, FourierOptions),
    "nlp": (run_nlp, NLPOptions),
}


def scenario(case: str, robot: RobotModel) -> Scenario:
    """The :class:`Scenario` of ``"free_end"`` (Section 4.1) or ``"end_constrained"`` (4.2)."""
    if case == "free_end":
        return free_end_scenario()
    if case == "end_constrained":
        return end_constrained_scenario(robot)
    raise ValueError(f"case: expected one of {sorted(CASES)}, got {case!r}")


def run_method(robot: RobotModel, scen: Scenario, name: str, options=None) -> MethodResult:
    """Run one method by name (``options``: its options dataclass, or None for the defaults —
    for ``eba`` the paper's values of the scenario's section)."""
    if name not in METHODS:
        raise ValueError(f"method: expected one of {sorted(METHODS)}, got {name!r}")
    fn, opt_cls = METHODS[name]
    if options is not None and not isinstance(options, opt_cls):
        raise TypeError(f"options for {name!r}: expected {opt_cls.__name__}, got {type(options).__name__}")
    return fn(robot, scen, options)


@dataclass
class CaseResult:
    """Results of :func:`run_case`: per method the :class:`MethodResult`, its
    :class:`MethodReport` and the simulated base-RPY trace ``(t, rpy [rad])``."""

    case: str
    scenario: Scenario
    results: dict = field(default_factory=dict)
    reports: dict = field(default_factory=dict)
    traces: dict = field(default_factory=dict)


def run_case(case: str, methods=None, options: dict | None = None, robot: RobotModel | None = None) -> CaseResult:
    """Run ``methods`` (default: all of the case, see :data:`CASES`) and evaluate each one.
    ``options``: ``{method name: options dataclass}``."""
    robot = robot or RobotModel.from_name("eba_ffsr")
    scen = scenario(case, robot)
    methods = CASES[case] if methods is None else tuple(methods)
    options = options or {}
    unknown = set(options) - set(METHODS)
    if unknown:
        raise ValueError(f"options for unknown methods {sorted(unknown)}; known: {sorted(METHODS)}")
    out = CaseResult(case, scen)
    for name in methods:
        log.info("running %s (%s)", name, case)
        res = run_method(robot, scen, name, options.get(name))
        rep, trace = evaluate(robot, res, scen, keep_traces=True)
        out.results[name], out.reports[name], out.traces[name] = res, rep, trace
    return out


# --------------------------------------------------------------------------- reporting
#: The issue's targets (measured and reported by the examples).
TARGETS = {"quintic_attitude_deg": "≈ 1 (paper: a degree)", "eba_attitude_deg": 0.01, "nlp_attitude_rad": 1e-6,
           "closed_chain_residual": 1e-6, "eba_runtime_s": 5.0, "nlp_runtime_s": 2.0, "fourier_runtime_s": 30.0}


def criteria(case_result: CaseResult, agree_rad: float = 1e-5) -> list[tuple[str, bool, str]]:
    """The examples' success criteria: ``(description, met, measured value)``.

    * every method ran to completion and its own final-attitude prediction agrees with the
      independent simulator within ``agree_rad``;
    * the NLP restores the attitude to ≤ 1e-6 rad with zero boundary velocity/acceleration;
    * ranking: EBA leaves less attitude error than the unoptimised baseline (quintic /
      leader-follower), and the NLP less than EBA;
    * BA (free end): velocity jumps at 0 and the end (≥ 1 °/s; EBA starts and ends at rest) and
      a larger jump than EBA's at the meeting t_m;
    * end-constrained: EBA's and the NLP's closed-chain residual ≤ 1e-6.

    The paper's absolute EBA figure (≤ 0.01°) and the run-time targets are reported by the
    examples but are not pass/fail criteria (see docs/eba.md for why).
    """
    R, P = case_result.results, case_result.reports
    out = []
    for name, rep in P.items():
        out.append((f"{name}: ran to completion", bool(rep.success), rep.message or "ok"))
        if np.isfinite(rep.planned_vs_simulated_rad):
            out.append((f"{name}: own final attitude = simulator's (≤ {agree_rad:g} rad)",
                        rep.planned_vs_simulated_rad <= agree_rad, f"{rep.planned_vs_simulated_rad:.2e} rad"))
    if "nlp" in P:
        err = np.deg2rad(P["nlp"].final_base_attitude_error_deg)
        out.append(("nlp: final attitude error ≤ 1e-6 rad (simulator)", err <= 1e-6, f"{err:.2e} rad"))
        bv = max(R["nlp"].info.get("boundary_velocity_max", np.inf), R["nlp"].info.get("boundary_acceleration_max", np.inf))
        out.append(("nlp: boundary velocity/acceleration = 0", bv <= 1e-9, f"{bv:.1e}"))
    base = "quintic" if "quintic" in P else "leader_follower" if "leader_follower" in P else None
    if base and "eba" in P:
        a, b = P["eba"].final_base_attitude_error_deg, P[base].final_base_attitude_error_deg
        out.append((f"ranking: eba < {base} (final attitude error)", a < b, f"{a:.3g}° < {b:.3g}°"))
    if "eba" in P and "nlp" in P:
        a, b = P["nlp"].final_base_attitude_error_deg, P["eba"].final_base_attitude_error_deg
        out.append(("ranking: nlp < eba (final attitude error)", a < b, f"{a:.2e}° < {b:.3g}°"))
    if "ba" in P and "eba" in P:
        jb = [v for _, v in P["ba"].velocity_jumps_deg_s]
        je = [v for _, v in P["eba"].velocity_jumps_deg_s]
        ok = (len(jb) == 3 and len(je) == 3 and min(jb[0], jb[2]) >= 1.0 and max(je[0], je[2]) <= 1e-6
              and jb[1] > je[1])
        out.append(("ba: velocity jumps at 0 and the end (≥ 1 °/s, eba: 0) and a larger one at t_m", ok,
                    "ba " + ", ".join(f"{v:.3g}" for v in jb) + " °/s; eba " + ", ".join(f"{v:.2g}" for v in je)))
    if case_result.scenario.closed_chain:
        for name in ("eba", "nlp"):
            if name in P:
                cc = P[name].max_closed_chain_residual
                out.append((f"{name}: closed-chain residual ≤ 1e-6", cc <= 1e-6, f"{cc:.2e}"))
    return out


def paper_targets(case_result: CaseResult) -> list[tuple[str, bool, str]]:
    """The paper's absolute figures as ``(target, met, measured value)``, for the methods that
    ran: the quintic's attitude error of the order of a degree (0.1°-10°), EBA ≤ 0.01°, the NLP ≤
    1e-6 rad, and the run times of :data:`TARGETS`. Reported next to :func:`criteria`, never
    folded into them: our model does not reproduce the paper's numbers exactly (EBA ends at
    0.1°-0.2°, see docs/eba.md), so a run can meet every criterion and miss targets — the
    examples print both counts."""
    P = case_result.reports
    out = []
    if "quintic" in P:
        a = P["quintic"].final_base_attitude_error_deg
        out.append(("quintic: final attitude error of the order of a degree (0.1°-10°)", 0.1 <= a <= 10.0, f"{a:.3g}°"))
    if "eba" in P:
        a = P["eba"].final_base_attitude_error_deg
        lim = float(TARGETS["eba_attitude_deg"])  # type: ignore[arg-type]  # a number in TARGETS
        out.append((f"eba: final attitude error ≤ {lim:g}° (the paper's figure)", a <= lim, f"{a:.3g}°"))
    if "nlp" in P:
        err = float(np.deg2rad(P["nlp"].final_base_attitude_error_deg))
        lim = float(TARGETS["nlp_attitude_rad"])  # type: ignore[arg-type]
        out.append((f"nlp: final attitude error ≤ {lim:g} rad", err <= lim, f"{err:.2e} rad"))
    for name in ("eba", "nlp", "fourier"):
        if name in P:
            limit = float(TARGETS[f"{name}_runtime_s"])  # type: ignore[arg-type]
            out.append((f"{name}: run time ≤ {limit:g} s", P[name].runtime_s <= limit, f"{P[name].runtime_s:.2f} s"))
    return out


def verdict(crit: list[tuple[str, bool, str]], targets: list[tuple[str, bool, str]]) -> str:
    """One honest line: how many criteria (pass/fail) and how many of the paper's targets (reported)
    were met, naming every missed target with its measured value."""
    missed = [f"{d} — measured {v}" for d, m, v in targets if not m]
    line = (f"criteria (pass/fail): {sum(c[1] for c in crit)}/{len(crit)} met; "
            f"the paper's targets (reported, not pass/fail): {sum(t[1] for t in targets)}/{len(targets)} met")
    return line + ("; missed: " + "; ".join(missed) if missed else "")


def _fmt3(v) -> str:
    return "(" + ", ".join(f"{x:+.3f}" if abs(x) >= 1e-3 or x == 0 else f"{x:+.0e}" for x in v) + ")"


def table(case_result: CaseResult) -> str:
    """Our figures next to the paper's, one line per method."""
    paper = PAPER_FIGURES.get(case_result.case, {})
    lines = [f"{'method':16s} {'final base RPY [deg] (ours)':31s} {'paper planned / real [deg]':38s} "
             f"{'joint err':>9s} {'max vel':>8s} {'max acc':>8s} {'max jump':>9s} {'run [s]':>8s} {'paper':>6s}"
             + ("  closed-chain" if case_result.scenario.closed_chain else "")]
    lines.append(f"{'':16s} {'':31s} {'':38s} {'[deg]':>9s} {'[deg/s]':>8s} {'[deg/s²]':>8s} {'[deg/s]':>9s}")
    for name, rep in case_result.reports.items():
        p = paper.get(name)
        ptxt = f"{_fmt3(p['planned_rpy_deg'])} / {_fmt3(p['real_rpy_deg'])}" if p else "— (not in the paper)"
        prun = f"{p['runtime_s']:6.0f}" if p else "     —"
        if p and p["runtime_s"] < 1:
            prun = f"{p['runtime_s']:6.2f}"
        flag = "" if rep.success else "  [" + rep.message + "]"
        line = (f"{name:16s} {_fmt3(rep.final_base_rpy_deg):31s} {ptxt:38s} {rep.final_joint_error_deg:9.2g} "
                f"{rep.max_velocity_deg_s:8.3g} {rep.max_acceleration_deg_s2:8.3g} {rep.max_velocity_jump_deg_s:9.2g} "
                f"{rep.runtime_s:8.2f} {prun}")
        if case_result.scenario.closed_chain:
            line += f"  {rep.max_closed_chain_residual:.1e}"
        lines.append(line + flag)
    return "\n".join(lines)


def case_json(case_result: CaseResult) -> dict:
    """``{"methods": {NAME: {...}}}`` with the issue's keys first (plus our extra figures)."""
    cc = case_result.scenario.closed_chain
    sc = case_result.scenario
    return {"case": case_result.case,
            "methods": {n: r.to_json(cc) for n, r in case_result.reports.items()},
            "paper": PAPER_FIGURES.get(case_result.case, {}),
            "scenario": {"theta0_deg": np.rad2deg(sc.theta0).tolist(), "thetaf_deg": np.rad2deg(sc.thetaf).tolist(),
                         "thetaf_paper_deg": np.rad2deg(sc.thetaf_paper).tolist(),
                         "goal_adjustment_deg": sc.goal_adjustment_deg,
                         "joint_angles": "URDF joint variables (D-H angle = value + θ offset)"}}


def save_trajectories(case_result: CaseResult, out_dir, joint_names) -> list:
    """``DIR/<NAME>.npz`` per method: ``t`` [s], ``q`` [rad] (joints only, Pinocchio order),
    ``qd`` [rad/s], ``joint_names``."""
    from pathlib import Path

    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, res in case_result.results.items():
        p = d / f"{name}.npz"
        res.save_npz(p, joint_names)
        paths.append(p)
    return paths
