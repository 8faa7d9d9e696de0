"""``optplan bench modelling``: trajectory problems a user writes with the public
:class:`~optplan.problem.OptProblem` API — build and solve times, IPOPT iterations and an
independent check of the result (Pinocchio, coal). Per task, in a new process: ``first`` — the
first problem (by default with an empty kernel cache: symbolic kernels, nothing compiled);
``warm`` — a second problem of the same structure after its kernels were compiled into the cache
(what every later run of a script sees), and a re-solve from its solution.

Tasks:

* ``reach`` — free-floating ``eba_ffsr``: arm A's hand 0.3 m to a target in 20 s, arm B still,
  base attitude restored at the end (N = 20), written with expressions, no user guess.
* ``reach_knots`` — the same on the knot transcription from a straight-line guess (the API
  before the kernel core).
* ``reach_free_time`` — the same with joint velocity/acceleration limits and free final time
  (minimum time plus a little jerk).
* ``reach_free_time_collision`` — the same plus ``CollisionAvoidance`` (0.01 m margin) with a
  sphere where arm A's wrist passes on the solution without it (:func:`reach_probe_scene`),
  checked by ``verify`` (coal, the base re-integrated); ``reach_free_time_collision_knots``: the
  same on the knot transcription.
* ``transport`` — the closed-chain transport (N = 50) with the shipped terms (collision planes
  included) on the kernel core; ``transport_custom``: the same plus two one-line terms: the
  object stays upright within 5° and an acceleration cost.

* ``ur5`` — a UR5 from example-robot-data (its vendor URDF and meshes through a robot file, the
  capsules fitted for planning) swinging its hand around one box, 0.02 m margin, checked by
  ``verify`` (coal, meshes); skipped without example-robot-data (``pip install "optplan[robots]"``).

``--peer rockit`` (extra ``rockit``: ``pip install rockit-meco``) also runs ``reach``,
``reach_free_time``, ``transport`` and ``transport_custom`` written in rockit
(:mod:`optplan.bench.rockit_peer`): the same problem, guess and checks, and prints the ratio of
rockit's build + solve CPU time to ours.
"""
from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

__all__ = ["TASKS", "run_task", "run", "format_rows"]

TASKS = ("reach", "reach_knots", "reach_free_time", "reach_free_time_collision", "reach_free_time_collision_knots",
         "transport", "transport_custom", "ur5")
Q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2]   # both arms of eba_ffsr, bent [rad]
#: The obstacle of ``reach_free_time_collision``: a sphere's centre [m] (world) and radius [m],
#: 0.12 m above where arm A's link 6 is halfway through the solution of ``reach_free_time``
#: (whose link 7 then passes 0.035 m inside it).
REACH_PROBE = (np.array([1.158, 0.439, 2.118]), 0.05)


def reach_probe_scene() -> Any:
    """The scene of ``reach_free_time_collision``: ``eba_ffsr`` and the sphere :data:`REACH_PROBE`."""
    import pinocchio as pin

    from optplan.scene import Obstacle, Scene

    c, r = REACH_PROBE
    return Scene(name="reach_probe", robot="eba_ffsr",
                 obstacles=(Obstacle(name="probe", shape="sphere", placement=pin.SE3(np.eye(3), c), radius=r),))


def _reach(free_time: bool, transcription: str = "auto", collision: bool = False) -> tuple[Any, Any]:
    import pinocchio as pin

    from optplan import RobotModel
    from optplan.problem import CollisionAvoidance, OptProblem
    from optplan.problem.frame_terms import BaseAttitude
    from optplan.problem.terms import Duration, JointAccelerationLimits, JointVelocityLimits, Smoothness

    robot = RobotModel.from_name("eba_ffsr")
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.configuration(Q0))
    target = data.oMf[robot.model.getFrameId("a_ee")].translation + 0.3 * np.array([0.6, 0.0, 0.8])
    t0 = (time.perf_counter(), time.process_time())   # wall [s], CPU [s]
    prob = OptProblem(robot, n_intervals=20, duration=20.0, free_time=free_time, duration_bounds=(2.0, 60.0),
                      transcription=transcription)
    prob.add_constraint(prob.q, lower=Q0, upper=Q0, at="start")
    prob.add_constraint(prob.qd, lower=0, upper=0, at=[0, 20])
    prob.add_constraint(prob.qdd, lower=0, upper=0, at=[0, 20])
    prob.add_constraint(prob.qd[7:], lower=0, upper=0)                         # arm B still
    goal = prob.parameter(3, target)                                            # a parameter: re-solves
    prob.add_constraint(prob.frame("a_ee").translation - goal, lower=0, upper=0, at="end")
    prob.add_constraint(BaseAttitude(at="end"))
    if free_time:
        prob.add_constraint(JointVelocityLimits(limit=0.1))
        prob.add_constraint(JointAccelerationLimits(limit=0.02))
        prob.add_cost(Duration())
        prob.add_cost(Smoothness("jerk"), weight=1e-2)
    else:
        prob.add_cost(Smoothness("jerk"))
    if collision:
        prob.add_constraint(CollisionAvoidance(reach_probe_scene(), margin=0.01, held_object=False, fixed_normals=True))
    if transcription == "knots":   # the knot transcription as before: a straight-line guess
        prob.set_initial_straight_line(Q0, Q0)
    return prob, (robot, target, t0)


def _check_reach(prob: Any, sol: Any, ctx: Any) -> dict[str, float]:
    import pinocchio as pin

    robot, target, _ = ctx
    data = robot.model.createData()
    qf = np.r_[sol.base_position[-1], sol.base_quat[-1], sol.q[-1]]
    pin.framesForwardKinematics(robot.model, data, qf)
    hand = float(np.linalg.norm(data.oMf[robot.model.getFrameId("a_ee")].translation - target))
    R = pin.Quaternion(sol.base_quat[-1][3], *sol.base_quat[-1][:3]).toRotationMatrix()
    ts = np.linspace(0, sol.duration, 10 * (len(sol.t) - 1) + 1)
    smp = sol.sample(ts)
    out = {"hand_error_m": hand, "base_attitude_error_rad": float(np.linalg.norm(pin.log3(R))),
           "arm_b_motion_rad": float(np.abs(smp["q"][:, 7:] - Q0[7:]).max()), "duration_s": sol.duration}
    if prob.free_time:
        out["max_velocity_rad_s"] = float(np.abs(smp["qd"]).max())
        out["max_acceleration_rad_s2"] = float(np.abs(smp["qdd"]).max())
    if "collision" in prob.terms:
        from optplan.verification import verify

        out["min_clearance_m"] = float(verify(robot, sol, reach_probe_scene(), held_object=False).min_clearance_m)
    return out


def _transport(custom: bool) -> tuple[Any, Any]:
    import casadi as ca

    from optplan import RobotModel
    from optplan.scene import Scene
    from optplan.tasks import transport_initial_path, transport_problem

    robot = RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load("transport")
    Q = transport_initial_path(robot, scene, 50, np.random.default_rng(0))
    if Q is None:
        raise RuntimeError("transport: no initial path")
    t0 = (time.perf_counter(), time.process_time())   # wall [s], CPU [s]
    prob, cc, _ = transport_problem(robot, scene, Q, fixed_normals=True, transcription="auto")
    if custom:
        assert scene.object is not None  # the transport scene holds an object
        G = scene.object.grasps["A"]
        R_obj = prob.frame(robot.model.frames[robot.arm("A").ee_frame_id].name).rotation @ ca.DM(G.rotation.T)
        prob.add_constraint(R_obj[2, 2], lower=np.cos(np.radians(5.0)), name="upright")   # one line
        prob.add_cost(prob.qdd, weight=1e-3, name="acceleration")                       # one line
    return prob, (robot, scene, cc, t0)


def _check_transport(prob: Any, sol: Any, ctx: Any) -> dict[str, float]:
    from optplan.verification import verify

    robot, scene, cc, _ = ctx
    rep = verify(robot, sol, scene, closed_chain=cc)
    out = {"closed_chain_residual": float(rep.max_closed_chain_residual), "min_clearance_m": float(rep.min_clearance_m)}
    if "upright" in prob.terms:
        out["min_upright_cos"] = _upright_min(robot, scene, sol)
    return out


UR5_FILE = """name = "ur5"
urdf = "package://example-robot-data/robots/ur_description/urdf/ur5_joint_limited_robot.urdf"
collision = "auto"

[arms.arm]
ee = "tool0"
"""
UR5_Q = (np.array([-0.9, -1.2, 1.6, -1.9, -1.57, 0.0]), np.array([0.9, -1.2, 1.6, -1.9, -1.57, 0.0]))   # [rad]
UR5_BOX = {"name": "box", "shape": "box", "size": [0.12, 0.12, 0.3], "xyz": [0.62, 0.11, 0.15]}   # [m]


class Skipped(Exception):
    """A task whose optional dependency is not installed."""


def _ur5_robot() -> Any:
    from optplan import RobotModel
    from optplan.model._robot_data import example_robot_data_dir

    if example_robot_data_dir() is None:
        raise Skipped("example-robot-data is not installed (pip install \"optplan[robots]\")")
    d = tempfile.mkdtemp(prefix="optplan_ur5_")
    path = os.path.join(d, "ur5.toml")
    with open(path, "w") as f:
        f.write(UR5_FILE)
    return RobotModel.from_name(path)


def _ur5() -> tuple[Any, Any]:
    from optplan.problem import OptProblem
    from optplan.problem.collision_term import CollisionAvoidance
    from optplan.problem.terms import JointBoundary, Smoothness
    from optplan.scene import Scene

    robot = _ur5_robot()
    scene = Scene.from_dict({"name": "ur5_box", "obstacles": [UR5_BOX]})
    q0, q1 = UR5_Q
    z = np.zeros(robot.nj)
    t0 = (time.perf_counter(), time.process_time())   # wall [s], CPU [s]
    prob = OptProblem(robot, n_intervals=20, duration=4.0)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
    prob.add_constraint(CollisionAvoidance(scene, margin=0.02, fixed_normals=True), name="collision")
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial_straight_line(q0, q1)      # through the box
    return prob, (robot, scene, None, t0)


def _check_ur5(prob: Any, sol: Any, ctx: Any) -> dict[str, float]:
    from optplan.verification import verify

    robot, scene, _, _ = ctx
    rep = verify(robot, sol, scene)
    return {"min_clearance_m": float(rep.min_clearance_m), "intervals": float(len(sol.t) - 1),
            "margin_held": float(rep.min_clearance_m >= 0.02 - 1e-4)}


def _forget_memory() -> None:
    """Drop what this process keeps in memory of the kernels, the robots' symbols and the NLP
    structures (the disk cache stays): the next problem is built as in a new process with a warm
    cache, but for the imports, the libraries the dynamic loader keeps and the memory the process
    already touched (the ``first`` row of ``--warm-cache`` is a new process's first problem)."""
    from optplan.problem import expressions, spline_core, spline_problem
    from optplan.problem.floating_kernels import FloatingKernels
    from optplan.problem.kernels import KernelCache

    for cls in (KernelCache, FloatingKernels):
        for kc in list(cls._by_digest.values()):
            kc._structures.clear()
            kc._fns.clear()
        cls._per_robot.clear()
        cls._by_digest.clear()
    expressions._SYMBOLS.clear()
    spline_problem._KNOT_KERNELS.clear()
    spline_core._QUAD_BLOCKS.clear()
    spline_core._FOUND_LIBS.clear()


def _solve_row(prob: Any, ctx: Any, check: Any) -> tuple[dict[str, Any], Any]:
    """Solve ``prob`` (made by a task's maker, ``ctx[-1]`` its start times) and its figures."""
    t0, c0 = ctx[-1]     # after loading the robot and scene, making the guess
    built = time.perf_counter()
    sol = prob.solve()
    total = time.perf_counter() - t0
    row = {"total_s": total, "total_cpu_s": time.process_time() - c0, "declare_s": built - t0,
           "setup_s": sol.setup_time, "build_s": built - t0 + sol.setup_time, "solve_s": sol.wall_time,
           "solve_cpu_s": sol.cpu_time, "iterations": sol.total_iterations, "attempts": len(sol.attempts),
           "success": bool(sol.success), "status": sol.status.value,
           "transcription": "bspline" if prob.uses_bspline() else "knots", **check(prob, sol, ctx)}
    return row, sol


def _resolve(prob: Any) -> dict[str, float]:
    """One re-solve of ``prob`` as it stands: its overhead besides IPOPT [s], split into the
    dense check between knots (timed again on its own, computed: neither the check nor the base
    attitudes the re-solve kept for inputs equal bit for bit) and the rest (setup, solution)."""
    from optplan.problem import guarantees

    t1, c1 = time.perf_counter(), time.process_time()
    s = prob.solve()
    wall, cpu = time.perf_counter() - t1, time.process_time() - c1
    kept, guarantees._CHECKS_KEPT = guarantees._CHECKS_KEPT, 0
    att, guarantees._ATTITUDES_KEPT = guarantees._ATTITUDES_KEPT, 0
    saved = dict(guarantees._ATTITUDES)   # the kept attitudes out of reach, put back after
    guarantees._ATTITUDES.clear()
    try:
        t2, c2 = time.perf_counter(), time.process_time()
        guarantees.check_between_knots(prob, s)
        chk, chk_cpu = time.perf_counter() - t2, time.process_time() - c2
    finally:
        guarantees._CHECKS_KEPT, guarantees._ATTITUDES_KEPT = kept, att
        guarantees._ATTITUDES.clear()
        guarantees._ATTITUDES.update(saved)
    return {"overhead_s": wall - s.wall_time, "overhead_cpu_s": cpu - s.cpu_time, "check_s": chk,
            "check_cpu_s": chk_cpu, "iterations": s.total_iterations, "success": bool(s.success)}


def run_task(name: str, repeat: int = 1, resolves: int = 1, new_values: bool = False) -> dict[str, Any]:
    """Task ``name`` in this process: the first problem, then ``repeat`` warm ones (the kernels
    compiled into the cache, the memory of them dropped before each: as a new process with a warm
    cache), with re-solves after ``set_initial(solution=...)`` and ``set_value``: ``resolves``
    rounds of (from the solution, again, after ``set_value``; the target moved by +1 cm and back
    in turn, or with ``new_values`` to a value not set before in every round: +1 mm per round),
    all kept in ``warm["resolves"]`` for their distribution."""
    if name not in TASKS:
        raise ValueError(f"task: expected one of {TASKS}, got {name!r}")
    make, check = {"reach": (lambda: _reach(False), _check_reach),
                   "reach_knots": (lambda: _reach(False, "knots"), _check_reach),
                   "reach_free_time": (lambda: _reach(True), _check_reach),
                   "reach_free_time_collision": (lambda: _reach(True, collision=True), _check_reach),
                   "reach_free_time_collision_knots": (lambda: _reach(True, "knots", collision=True), _check_reach),
                   "transport": (lambda: _transport(False), _check_transport),
                   "transport_custom": (lambda: _transport(True), _check_transport),
                   "ur5": (_ur5, _check_ur5)}[name]
    try:
        make()
    except Skipped as exc:
        return {"task": name, "skipped": str(exc)}
    rows: dict[str, Any] = {}
    prob, ctx = make()
    rows["first"], _ = _solve_row(prob, ctx, check)
    prob, ctx = make()               # the kernels of this structure compiled into the cache (not timed)
    if prob.uses_bspline():
        prob.compile_kernels = True
        prob.solve()
    reps = []
    for _ in range(max(1, int(repeat))):
        _forget_memory()
        prob, ctx = make()
        row, sol = _solve_row(prob, ctx, check)
        reps.append(row)
    rows["warm"] = dict(reps[0])
    if len(reps) > 1:
        rows["warm"]["repeats"] = {k: [r[k] for r in reps] for k in ("total_s", "total_cpu_s", "build_s",
                                                                     "solve_s", "solve_cpu_s")}
    # re-solves: what a warm start / a new parameter value costs besides IPOPT (the last warm problem)
    if prob.uses_bspline():
        # the garbage of the builds above collected now: a collection of it (the benchmark's, not
        # the re-solves': they make no reference cycles) fell on the tenth re-solve after set_value
        gc.collect()
        every: dict[str, list[dict[str, float]]] = {"resolve": [], "resolve_again": [], "set_value": []}
        target = prob._params[0].value.ravel().copy() if prob._params else None
        for i in range(max(1, int(resolves))):
            prob.set_initial(solution=sol)
            every["resolve"].append(_resolve(prob))
            prob.set_initial(solution=sol)            # again: the warm-start IPOPT instance exists now
            every["resolve_again"].append(_resolve(prob))
            if target is not None:
                dy = 0.001 * (i + 1) if new_values else 0.01 if i % 2 == 0 else 0.0
                prob.set_value(prob._params[0].sym, target + [0.0, dy, 0.0])
                every["set_value"].append(_resolve(prob))
        for key, v in every.items():
            if v:
                rows["warm"][key] = v[0]
        if resolves > 1:
            rows["warm"]["resolves"] = {key: {k: [r[k] for r in v] for k in v[0]} for key, v in every.items() if v}
    return {"task": name, **rows}


PEER_TASKS = ("reach", "reach_free_time", "transport", "transport_custom")


def run_peer(name: str) -> dict[str, Any]:
    """Task ``name`` written in rockit (:mod:`optplan.bench.rockit_peer`), checked as ours."""
    from . import rockit_peer

    if name not in PEER_TASKS:
        raise ValueError(f"peer task: expected one of {PEER_TASKS}, got {name!r}")
    if not rockit_peer.available():
        return {"task": name, "peer": "rockit", "skipped": "rockit is not installed (pip install \"optplan[rockit]\")"}
    from optplan.verification import verify

    if name in ("reach", "reach_free_time"):
        free = name == "reach_free_time"
        prob, ctx = _reach(free)
        robot, target, _ = ctx
        r = rockit_peer.reach(robot, Q0, target, "a_ee", N=prob.N, duration=prob.duration, free_time=free,
                              duration_bounds=prob.duration_bounds)
        sol = r.pop("solution")
        rep = verify(robot, sol, None)
        return {"task": name, "peer": "rockit", **r, **_check_reach(prob, sol, ctx),
                "verify_base_attitude_mismatch_rad": float(rep.base_attitude_mismatch_rad),
                "note": rockit_peer.REACH_NOTE + "; guess: the start held" + ("; FreeTime" if free else "")}

    custom = name == "transport_custom"
    prob, (robot, scene, cc, _) = _transport(custom)
    Q = prob.tp.unpack(prob._x0)["q"]           # the same guess as ours
    upright = None
    if custom:
        assert scene.object is not None  # the transport scene holds an object
        upright = (robot.arm("A").ee_frame_id, scene.object.grasps["A"].rotation, float(np.cos(np.radians(5.0))))
    r = rockit_peer.transport(robot, Q, cc, duration=prob.duration, upright=upright,
                              acceleration_weight=1e-3 if custom else 0.0)
    sol = r.pop("solution")
    rep = verify(robot, sol, scene, closed_chain=cc)
    out = {"task": name, "peer": "rockit", **r, "closed_chain_residual": float(rep.max_closed_chain_residual),
           "min_clearance_m": float(rep.min_clearance_m), "note": "no collision rows (rockit has no collision model)"}
    if custom:
        out["min_upright_cos"] = _upright_min(robot, scene, sol)
    return out


def _upright_min(robot: Any, scene: Any, sol: Any) -> float:
    """The smallest ``(R_hand R_graspᵀ)[2, 2]`` of arm A along ``sol`` (10 samples per interval,
    Pinocchio): the upright check of ``transport_custom`` for a solution without our terms."""
    import pinocchio as pin

    G = scene.object.grasps["A"]
    fid = robot.arm("A").ee_frame_id
    data = robot.model.createData()
    ts = np.linspace(0, sol.duration, 10 * (len(sol.t) - 1) + 1)
    out = []
    for q in sol.sample(ts)["q"]:
        pin.framesForwardKinematics(robot.model, data, q)
        out.append(float((data.oMf[fid].rotation @ np.asarray(G.rotation).T)[2, 2]))
    return min(out)


def run(tasks: list[str], cold: bool = True, repeat: int = 1, resolves: int = 1,
        new_values: bool = False) -> list[dict[str, Any]]:
    """Each task in a new process (``cold``: with an empty ``OPTPLAN_CACHE``, background compiles
    off), its first and warm figures (``repeat`` warm problems, ``resolves`` rounds of re-solves,
    ``new_values``: :func:`run_task`)."""
    out = []
    for t in tasks:
        env = dict(os.environ)
        with tempfile.TemporaryDirectory() as tmp:
            if cold:
                env["OPTPLAN_CACHE"] = tmp
                env["OPTPLAN_BACKGROUND_COMPILE"] = "0"
            p = subprocess.run([sys.executable, "-m", "optplan.bench.modelling", "--one", t, "--repeat", str(repeat),
                                "--resolves", str(resolves)] + (["--new-values"] if new_values else []),
                               env=env, capture_output=True, text=True, check=False)
        if p.returncode != 0:
            out.append({"task": t, "error": (p.stderr or p.stdout).strip().splitlines()[-1:]})
            continue
        out.append(json.loads(p.stdout.strip().splitlines()[-1]))
    return out


def _spread(v: list[float]) -> str:
    """``median [min–max]`` of ``v``."""
    return f"{np.median(v):.3f} [{min(v):.3f}-{max(v):.3f}]"


def format_rows(rows: list[dict[str, Any]]) -> str:
    lines = [f"{'task':18} {'run':6} {'tr':8} {'total s':>8} {'cpu s':>6} {'build s':>8} {'solve s':>8} {'cpu s':>6} "
             f"{'it':>4}  ok  check"]
    for r in rows:
        if "error" in r:
            lines.append(f"{r['task']:18} error: {r['error']}")
            continue
        if "skipped" in r:
            lines.append(f"{r['task']:18} skipped: {r['skipped']}")
            continue
        for run_ in ("first", "warm"):
            x = r[run_]
            chk = ", ".join(f"{k}={v:.3g}" for k, v in x.items() if isinstance(v, float) and (
                k.endswith(("_m", "_rad", "_cos", "residual", "_s2", "_rad_s")) or k in ("duration_s", "intervals",
                                                                                      "margin_held")))
            build = x.get("build_s", x.get("declare_s", 0.0) + x["setup_s"])
            lines.append(f"{r['task']:18} {run_:6} {x['transcription']:8} {x['total_s']:8.2f} "
                         f"{x.get('total_cpu_s', float('nan')):6.2f} {build:8.2f} "
                         f"{x['solve_s']:8.2f} {x['solve_cpu_s']:6.2f} {x['iterations']:4d}  {'yes' if x['success'] else 'NO ':3} {chk}")
            if "repeats" in x:
                rp = x["repeats"]
                lines.append(f"{'':18} {len(rp['total_s'])} warm problems, median [min-max]: total {_spread(rp['total_s'])} s, "
                             f"cpu {_spread(rp['total_cpu_s'])} s, build {_spread(rp['build_s'])} s, "
                             f"IPOPT {_spread(rp['solve_s'])} s (cpu {_spread(rp['solve_cpu_s'])} s)")
            for key, v in x.get("resolves", {}).items():
                o, oc, ck = (1e3 * np.array(v[k]) for k in ("overhead_s", "overhead_cpu_s", "check_s"))
                lines.append(f"{'':18} {len(o)} re-solves ({key}): overhead besides IPOPT median {np.median(o):.1f} ms "
                             f"[{o.min():.1f}-{o.max():.1f}], p90 {np.percentile(o, 90):.1f}, {int(np.sum(o <= 10.0))}/"
                             f"{len(o)} <= 10 ms; cpu median {np.median(oc):.1f} ms [{oc.min():.1f}-{oc.max():.1f}]; "
                             f"dense check median {np.median(ck):.1f} ms; it {min(v['iterations'])}-"
                             f"{max(v['iterations'])}, {sum(v['success'])}/{len(o)} ok")
            for key, what in (("resolve", "re-solve from its solution"), ("resolve_again", "again"),
                              ("set_value", "after set_value (target moved)")):
                if key in x:
                    v = x[key]
                    lines.append(f"{'':18} {what}: overhead besides IPOPT {1e3 * v['overhead_s']:.1f} ms, "
                                 f"cpu {1e3 * v['overhead_cpu_s']:.1f} ms (of it the dense check between knots "
                                 f"{1e3 * v['check_s']:.1f} ms, cpu {1e3 * v.get('check_cpu_s', float('nan')):.1f} ms), "
                                 f"{v['iterations']} it, {'ok' if v['success'] else 'FAILED'}")
    return "\n".join(lines)


def run_peers(tasks: list[str]) -> list[dict[str, Any]]:
    """rockit's rows of ``tasks`` (those it has), each in a new process."""
    out = []
    for t in tasks:
        if t not in PEER_TASKS:
            continue
        p = subprocess.run([sys.executable, "-m", "optplan.bench.modelling", "--one-peer", t],
                           capture_output=True, text=True, check=False)
        if p.returncode != 0:
            out.append({"task": t, "peer": "rockit", "error": (p.stderr or p.stdout).strip().splitlines()[-1:]})
            continue
        out.append(json.loads(p.stdout.strip().splitlines()[-1]))
    return out


def _median_cpu(x: dict[str, Any]) -> float:
    """Build + solve CPU time [s] of a row: the median of its warm problems if repeated."""
    return float(np.median(x["repeats"]["total_cpu_s"])) if "repeats" in x else float(x.get("total_cpu_s", 0.0))


def format_peers(peers: list[dict[str, Any]], rows: list[dict[str, Any]]) -> str:
    """rockit's rows and the ratio of its build + solve CPU time to ours (warm: the median of the
    warm problems; first), with whether both verified the same checks."""
    ours = {r["task"]: r for r in rows if "first" in r}
    lines = []
    for p in peers:
        head = f"{p['task']:18} rockit "
        if "skipped" in p or "error" in p:
            lines.append(head + (f"skipped: {p['skipped']}" if "skipped" in p else f"error: {p['error']}"))
            continue
        chk = ", ".join(f"{k}={v:.3g}" for k, v in p.items() if isinstance(v, float) and (
            k.endswith(("_m", "_rad", "residual", "_cos", "_s2", "_rad_s")) or k == "duration_s"))
        line = (head + f"total {p['total_s']:.2f} s, cpu {p['total_cpu_s']:.2f} s, {p['iterations']} it, "
                f"{'ok' if p['success'] else 'FAILED'}, {chk} ({p['note']})")
        o = ours.get(p["task"])
        if o is not None:
            cpu = {r: _median_cpu(o[r]) for r in ("warm", "first")}
            line += "; rockit cpu / ours: " + ", ".join(
                f"{p['total_cpu_s'] / c:.1f}x ({r})" for r, c in cpu.items() if c > 0)
        lines.append(line)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="optplan bench modelling", description=__doc__.split("\n\n")[0])
    ap.add_argument("--tasks", default=",".join(TASKS), help="comma-separated subset of " + ",".join(TASKS))
    ap.add_argument("--warm-cache", action="store_true", help="keep the kernel cache (default: each task's "
                    "first run in a new process with an empty cache)")
    ap.add_argument("--repeat", type=int, default=1, help="warm problems per task (median and spread printed; "
                    "default 1)")
    ap.add_argument("--resolves", type=int, default=1, help="rounds of re-solves of the last warm problem (from "
                    "its solution, again, after set_value), their overhead's distribution printed (default 1)")
    ap.add_argument("--new-values", action="store_true", help="the re-solves after set_value move the target "
                    "to a value not set before in every round (+1 mm per round; default: +1 cm and back in turn)")
    ap.add_argument("--json", help="write the rows as JSON to this path")
    ap.add_argument("--peer", choices=["rockit"], help="also run the tasks rockit can write ("
                    + ", ".join(PEER_TASKS) + ") in rockit (extra 'rockit'); skipped when it is not installed")
    ap.add_argument("--one", help=argparse.SUPPRESS)
    ap.add_argument("--one-peer", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(run_task(args.one, args.repeat, args.resolves, args.new_values)))
        return 0
    if args.one_peer:
        print(json.dumps(run_peer(args.one_peer)))
        return 0
    tasks = [t.strip() for t in args.tasks.split(",") if t.strip()]
    bad = [t for t in tasks if t not in TASKS]
    if bad:
        ap.error(f"unknown tasks {bad}; choose from {', '.join(TASKS)}")
    if args.repeat < 1:
        ap.error(f"--repeat: expected an integer ≥ 1, got {args.repeat}")
    if args.resolves < 1:
        ap.error(f"--resolves: expected an integer ≥ 1, got {args.resolves}")
    rows = run(tasks, cold=not args.warm_cache, repeat=args.repeat, resolves=args.resolves,
               new_values=args.new_values)
    print(format_rows(rows))
    peers = run_peers(tasks) if args.peer else []
    if peers:
        print(format_peers(peers, rows))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows + peers, f, indent=1)
    return 0 if all("skipped" in r or ("error" not in r and r["first"]["success"] and r["warm"]["success"])
                    for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
