"""``optplan reproduce PAPER [--quick] [--out DIR]``: one command per source paper.

Runs that paper's reproduction (the example scripts in the source tree's ``examples/`` folder,
or optplan's own benchmark commands), streams their output (which prints our figures next to the
paper's), and writes into ``DIR``: each step's log and JSON, the PNG figures, HTML views of the
trajectories (``optplan view``; needs the ``viz`` extra) and ``DIR/reproduce.json`` with every
step's command, exit code and run time. At the end it prints our headline figures next to the
paper's. ``--quick`` runs a reduced version (fewer trials, methods or cases) in under a minute.

Papers: ``tcbirrt`` (TCBiRRT, closed-chain dual-arm planning on space-solar-power-station
scenes), ``eba`` (EBA base-attitude restoration of a dual-arm free-floating robot), ``dshdasr``
(space-arc equivalent kinematics of a discrete + serpentine dual-arm robot), ``spline-rrt``
(Spline-RRT*, coordinated dual-arm planning for a free-floating robot) and ``oc-rrt`` (OC-RRT,
orientation-constrained RRT for spherical-wrist dual arms).
"""
from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from . import interrupt

__all__ = ["PAPERS", "Paper", "Step", "ReproduceError", "examples_dir", "plan_steps", "reproduce"]


class ReproduceError(RuntimeError):
    """A reproduction cannot start (missing script, unknown paper)."""


@dataclass(frozen=True)
class Step:
    """One command of a reproduction: ``argv`` after the Python interpreter; ``json``: the JSON it
    writes (if any); ``trajectories``: npz files or folders of npz it writes, with their robot."""

    name: str
    argv: tuple
    json: str | None = None
    trajectories: tuple = ()     # ((path, robot name, scene name or None), ...)


@dataclass(frozen=True)
class Paper:
    key: str
    title: str
    scripts: tuple               # example scripts it needs (file names in examples/)
    steps: Callable              # (out: Path, quick: bool, examples: Path) -> list[Step]
    summary: Callable | None = None   # (out: Path, steps: list[Step]) -> list[str]
    extra_views: Callable | None = None   # (out: Path, quick: bool) -> list[Path]


log = logging.getLogger(__name__)

def examples_dir() -> Path:
    """The ``examples/`` folder of the source tree optplan runs from."""
    return Path(__file__).resolve().parent.parent / "examples"


def _py(*args) -> tuple:
    return tuple(str(a) for a in args)


# --------------------------------------------------------------------------- TCBiRRT
def _tcbirrt_planners() -> str:
    """The paper's seven planners (Tables 2-3), less the learned ones when ``optplan[learned]`` is absent."""
    from .bench.tcbirrt_tables import PAPER_ORDER
    from .planners.learned import LEARNED, available

    return ",".join(p for p in PAPER_ORDER if available() or p not in LEARNED)


def _tcbirrt_steps(out: Path, quick: bool, ex: Path) -> list[Step]:
    bench = out / "bench"
    if quick:
        args = ["--scene", "1,2,3", "--trials", "5", "--planners", _tcbirrt_planners(), "--time-limit", "10"]
    else:
        args = ["--scene", "1,2,3", "--trials", "100", "--planners", _tcbirrt_planners(), "--time-limit", "10",
                "--jobs", "2"]
    steps = [Step("bench", _py("-m", "optplan.cli", "bench", "tcbirrt", *args, "--out", bench, "--no-progress"),
                  json=str(bench / "summary.json"))]
    if not quick:
        steps.append(Step("plan", _py("-m", "optplan.cli", "plan", "--scene", "1", "--json", out / "plan.json",
                                      "--save", out / "traj" / "plan_scene1.npz", "--html", out / "plan_scene1.html",
                                      "--plot", out / "fig"), json=str(out / "plan.json")))
    return steps


def _tcbirrt_view(out: Path, quick: bool) -> list[Path]:
    """The planner's path of trial 0 of scene 1 (no optimizer) as an HTML view: what TCBiRRT
    returns, configurations timed at 0.5 rad/s of joint motion."""
    import numpy as np

    from .model.robot import RobotModel
    from .planners import make_planner
    from .scene import Scene
    from .trials import TrialGenerator
    from .viz.html import ViewOptions, write_trajectory_html

    robot = RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load("ssps_scene1")
    trial = TrialGenerator(robot, scene).generate(0, 0)
    res = make_planner("tcbirrt", robot, scene).plan(trial.q_start, trial.q_goal, time_limit=10.0, seed=trial.seed)
    if not res.success:
        log.warning("TCBiRRT found no path for the view: %s", res.status.value)
        return []
    P = np.asarray(res.path, float)
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1) / 0.5)])
    from ._io import atomic_path

    with atomic_path(out / "traj" / "tcbirrt_path_scene1.npz") as tmp, open(tmp, "wb") as f:
        np.savez(f, t=t, q=P, constrained=np.asarray(res.constrained, bool),
                 robot=np.array(robot.name), scene=np.array(scene.name))
    return [write_trajectory_html(out / "tcbirrt_path_scene1.html", robot, scene, t, P, constrained=res.constrained,
                                  options=ViewOptions(title="TCBiRRT path, ssps_scene1 trial 0 (before optimization)"))]


def _tcbirrt_summary(out: Path, steps) -> list[str]:
    from .bench.tcbirrt_tables import format_tables

    p = out / "bench" / "summary.json"
    if not p.exists():
        return ["  (no benchmark summary)"]
    summ = json.loads(p.read_text())
    cfg_path = out / "bench" / "config.json"
    cfg = json.loads(cfg_path.read_text()) if cfg_path.exists() else {}
    lines = ["  " + ln for ln in format_tables(summ, float(cfg.get("time_limit", 10.0)), cfg.get("clock", "cpu")).splitlines()]
    lines.append(f"  Fig. 6 (p(t) per scene): {out / 'bench' / 'fig6_success_rate.png'}")
    lines.append("  (ours: CPU seconds per query, this machine; paper: wall seconds at t = 1000 s, Python + "
                 "MuJoCo on an i9-10900K; our scene geometry is our own: the paper does not give it)")
    return lines


# --------------------------------------------------------------------------- EBA
def _eba_steps(out: Path, quick: bool, ex: Path) -> list[Step]:
    fe = ["--json", out / "eba_free_end.json", "--plot", out / "fig", "--save", out / "traj" / "free_end"]
    steps = [Step("free_end", _py(ex / "eba_free_end.py", *fe,
                                  *(["--methods", "quintic,eba,nlp", "--no-variant"] if quick else [])),
                  json=str(out / "eba_free_end.json"), trajectories=((str(out / "traj" / "free_end"), "eba_ffsr", None),))]
    if not quick:
        ec = ["--json", out / "eba_end_constraints.json", "--plot", out / "fig", "--save", out / "traj" / "end_constrained"]
        steps.append(Step("end_constraints", _py(ex / "eba_end_constraints.py", *ec),
                          json=str(out / "eba_end_constraints.json"),
                          trajectories=((str(out / "traj" / "end_constrained"), "eba_ffsr", None),)))
    return steps


def _fmt_rpy(v) -> str:
    return "/" if v is None else "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"


def _eba_summary(out: Path, steps) -> list[str]:
    lines = [f"  {'case':16s} {'method':16s} {'final base RPY [deg] (ours)':>30s}  {'paper planned / real [deg]':>44s}"]
    for name in ("eba_free_end.json", "eba_end_constraints.json"):
        p = out / name
        if not p.exists():
            continue
        d = json.loads(p.read_text())
        for m, r in d["methods"].items():
            pp = d.get("paper", {}).get(m)
            ps = "— (not in the paper)" if pp is None else (f"{_fmt_rpy(pp.get('planned_rpy_deg'))} / "
                                                             f"{_fmt_rpy(pp.get('real_rpy_deg'))}")
            lines.append(f"  {d['case']:16s} {m:16s} {_fmt_rpy(r.get('final_base_rpy_deg')):>30s}  {ps:>44s}")
    lines.append("  (ours: attitude from the independent free-floating simulator; see docs/eba.md)")
    return lines


# --------------------------------------------------------------------------- DSHDASR
def _dshdasr_steps(out: Path, quick: bool, ex: Path) -> list[Step]:
    args = ["--json", out / "dshdasr.json", "--plot", out / "fig"]
    if _supports(ex / "dshdasr_transposition.py", "--save"):
        args += ["--save", out / "traj" / "dshdasr.npz", "--html", out / "dshdasr.html"]
    return [Step("transposition", _py(ex / "dshdasr_transposition.py", *args, *(["--no-cases"] if quick else [])),
                 json=str(out / "dshdasr.json"))]


def _dshdasr_summary(out: Path, steps) -> list[str]:
    from .papers.dshdasr import PAPER

    p = out / "dshdasr.json"
    if not p.exists():
        return ["  (no JSON)"]
    d = json.loads(p.read_text())
    lines = [f"  {'':36s} {'ours':>10s} {'paper':>10s}"]
    for key, label in (("max_tip_position_error_a_m", "max tip position error Arm-a [m]"),
                       ("max_tip_attitude_error_a_rad", "max tip attitude error Arm-a [rad]"),
                       ("max_tip_position_error_b_m", "max tip position error Arm-b [m]"),
                       ("max_tip_direction_error_b_rad", "max tip direction error Arm-b [rad]")):
        if key in d:
            lines.append(f"  {label:36s} {d[key]:10.2e} {PAPER.get(key, float('nan')):10.2e}")
    if d.get("cases"):
        paper_cases = cast("list[str]", PAPER["cases"])
        lines.append(f"  extra goals of Table 1: {' '.join(d['cases'])} (paper {' '.join(paper_cases)})")
    return lines


# --------------------------------------------------------------------------- scripts of other papers
def _help_text(script: Path) -> str:
    try:
        r = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120)
        return r.stdout + r.stderr
    except (OSError, subprocess.TimeoutExpired):
        return ""


def _supports(script: Path, flag: str) -> bool:
    if not script.exists():
        return False
    return flag in script.read_text(encoding="utf-8", errors="replace")


def _generic_steps(script_name: str, stem: str, quick_flags: tuple = ("--quick",), robot: str | None = None) -> Callable:
    """Steps of a paper script whose options are read off its ``--help``: ``--json``, ``--plot``,
    ``--html`` when offered; ``--save DIR`` (a folder of npz trajectories, viewed as ``robot``)
    when offered and ``robot`` is known; with ``--quick`` the first of ``quick_flags`` it offers."""
    def steps(out: Path, quick: bool, ex: Path) -> list[Step]:
        script = ex / script_name
        text = _help_text(script)
        args: list = []
        js = None
        traj: tuple = ()
        if "--json" in text:
            js = out / f"{stem}.json"
            args += ["--json", js]
        if "--plot" in text:
            args += ["--plot", out / "fig"]
        if "--html" in text:
            args += ["--html", out / f"{stem}.html"]
        if "--save" in text and robot is not None:
            args += ["--save", out / "traj" / stem]
            traj = ((str(out / "traj" / stem), robot, None),)
        if quick:
            flag = next((f for f in quick_flags if f in text), None)
            if flag is not None:
                args.append(flag)
        return [Step(stem, _py(script, *args), json=None if js is None else str(js), trajectories=traj)]
    return steps


PAPERS: dict[str, Paper] = {
    "tcbirrt": Paper("tcbirrt", "TCBiRRT: task-space constrained bidirectional RRT for a closed-chain dual-arm robot "
                     "assembling a space solar power station", (), _tcbirrt_steps, _tcbirrt_summary, _tcbirrt_view),
    "eba": Paper("eba", "EBA: base-attitude restoration of a dual-arm free-floating space robot",
                 ("eba_free_end.py", "eba_end_constraints.py"), _eba_steps, _eba_summary),
    "dshdasr": Paper("dshdasr", "Space-arc equivalent kinematics of a discrete + serpentine dual-arm space robot "
                     "(target transposition)", ("dshdasr_transposition.py",), _dshdasr_steps, _dshdasr_summary),
    "spline-rrt": Paper("spline-rrt", "Spline-RRT*: coordinated dual-arm planning for a free-floating space robot",
                        ("spline_rrt_star.py",), _generic_steps("spline_rrt_star.py", "spline_rrt_star",
                                                                 ("--quick", "--no-optimize"), "splinerrt_ffsr")),
    "oc-rrt": Paper("oc-rrt", "OC-RRT: orientation-constrained RRT for spherical-wrist dual arms",
                    ("oc_rrt.py",), _generic_steps("oc_rrt.py", "oc_rrt")),
}


def plan_steps(paper: str, out, quick: bool = False, examples: Path | None = None) -> list[Step]:
    """The steps ``reproduce`` would run (raises :class:`ReproduceError` for an unknown paper or a
    missing script)."""
    paper = paper.replace("_", "-")   # the package keys (optplan.papers.spline_rrt) name the same papers
    if paper not in PAPERS:
        raise ReproduceError(f"unknown paper {paper!r}; expected one of {', '.join(PAPERS)}")
    p = PAPERS[paper]
    ex = Path(examples) if examples is not None else examples_dir()
    missing = [s for s in p.scripts if not (ex / s).exists()]
    if missing:
        raise ReproduceError(f"{p.title}: the reproduction script {', '.join(str(ex / s) for s in missing)} is "
                             "missing; `optplan reproduce` runs the examples of a source checkout of optplan "
                             "(git clone, then pip install -e .)")
    return p.steps(Path(out), quick, ex)


def _views(step: Step, out: Path) -> list[Path]:
    """HTML views of the npz trajectories a step wrote (needs the viz extra)."""
    from .viz.html import VizUnavailable, view_file

    made = []
    for path, robot, scene in step.trajectories:
        p = Path(path)
        files = sorted(p.glob("*.npz")) if p.is_dir() else ([p] if p.exists() else [])
        for f in files:
            try:
                made.append(view_file(f, robot=robot, scene=scene, out=out / "html" / f"{p.name}_{f.stem}.html"))
            except VizUnavailable as exc:
                log.warning("no HTML views: %s", exc)
                return made
            except Exception as exc:   # a view is an extra: report it, keep the run's other outputs
                log.warning("no HTML view of %s: %s: %s", f, type(exc).__name__, exc)
    return made


def reproduce(paper: str, out="reproduce", quick: bool = False, html: bool = True,
              examples: Path | None = None, say=print) -> dict:
    """Run a paper's reproduction; returns (and writes to ``out/reproduce.json``) the record of
    its steps. ``say``: where the progress lines go (the command line: ``print``). Raises
    :class:`ReproduceError` when it cannot start."""
    steps = plan_steps(paper, out, quick, examples)
    p = PAPERS[paper.replace("_", "-")]
    out = Path(out)
    (out / "traj").mkdir(parents=True, exist_ok=True)
    say(f"optplan reproduce {paper}{' --quick' if quick else ''}: {p.title}")
    say(f"  output folder {out}")
    record: dict[str, Any] = {"paper": paper, "title": p.title, "quick": quick, "steps": [], "files": []}
    t_all = time.perf_counter()
    ok = True
    for k, st in enumerate(steps):
        interrupt.progress(k, len(steps), "steps")
        say(f"\n$ python {' '.join(st.argv)}", flush=True)
        t0 = time.perf_counter()
        log_path = out / f"{st.name}.log"
        with open(log_path, "w") as log_file:
            proc = subprocess.Popen([sys.executable, *st.argv], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    text=True, bufsize=1, preexec_fn=interrupt.die_with_parent)
            try:
                assert proc.stdout is not None   # stdout=PIPE
                for line in proc.stdout:
                    sys.stdout.write(line)
                    log_file.write(line)
                rc = proc.wait()
            except BaseException:   # interrupted: the step's process ends with this one
                interrupt.stop_process(proc)
                raise
        dt = time.perf_counter() - t0
        ok &= rc == 0
        record["steps"].append({"name": st.name, "argv": list(st.argv), "exit_code": rc, "run_time_s": dt,
                                "log": str(log_path), "json": st.json})
        say(f"  [{st.name}: exit code {rc}, {dt:.1f} s]")
        if html:
            for v in _views(st, out):
                record["files"].append(str(v))
    if html and p.extra_views is not None:
        try:
            for v in p.extra_views(out, quick):
                record["files"].append(str(v))
        except ImportError as exc:
            log.warning("no HTML view: %s", exc)
    record["files"] += sorted(str(f) for f in out.rglob("*") if f.suffix in (".png", ".html", ".json")
                              and str(f) not in record["files"])
    record["run_time_s"] = time.perf_counter() - t_all
    record["success"] = bool(ok)
    if p.summary is not None:
        say(f"\n{p.title}: ours next to the paper's")
        for line in p.summary(out, steps):
            say(line)
    from ._io import write_json

    interrupt.progress(len(steps), len(steps), "steps")
    write_json(out / "reproduce.json", record)   # last: after the files it lists
    html_files = [f for f in record["files"] if f.endswith(".html")]
    say(f"\nrun time {record['run_time_s']:.1f} s; {'all steps succeeded' if ok else 'SOME STEPS FAILED'}; "
          f"record {out / 'reproduce.json'}")
    for f in html_files:
        say(f"  3D view: {f}")
    return record




