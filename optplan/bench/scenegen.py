"""Parametric scene generator: fresh random scenes of the TCBiRRT robot carrying the SSPS module, in
six families, each draw checked for feasibility before it is used.

Families (obstacles placed relative to the start and goal object poses ``s``, ``g``; all sizes [m]):

* ``wall`` — a finite wall (3.0-4.2 m square, 0.08-0.2 m thick) across the way from ``s`` to ``g``,
  tilted up to 20°, with an opening of random size: 0.95-1.6 m across the module's path, 3.1-3.6 m
  along the module's long axis, of which only the middle 1.8 m is closed beyond the opening (the
  arms pass at its ends, as in the hard scene "window"), turned up to ±15° in its plane and
  off-centre by up to 0.3 m;
* ``bay`` — the goal recessed in a bay of random depth (0.9-1.6 m, at least the object's depth + 0.1 m), opening towards a random yaw
  (±35° about +x), clearances 0.1-0.3 m above and below and 0.05-0.2 m at the back;
* ``corridor`` — a corridor with a bend: the way ``s → w → g`` through a random waypoint ``w``, each
  leg between two slabs (1.8 m wide) at 0.1-0.3 m from the object;
* ``clutter`` — 4-16 random boxes, spheres and capsules (0.1-0.5 m) in the region spanned by ``s``
  and ``g`` (grown by 0.8 m);
* ``truss`` — 2-5 slender beams (0.12-0.25 m square, 2.5-4 m long) crossing the region, mostly
  horizontal;
* ``overhang`` — a plate 0.15-0.4 m above the start object, shifted by up to ±0.8 m, and optionally a
  post beside the way.

Start and goal come from a shipped scene of the same robot and object (a hard-suite or SSPS scene:
its object poses and their configurations), possibly swapped.

A draw is kept only when it is *feasible for the robot*: first the cheap necessary conditions of
:func:`feasibility` (both end configurations collision-free, a trial generated, a path of the object
alone found), then a WITNESS (:mod:`optplan.bench.scene_witness`): a path of the dual arm for the
benchmark's own query on the scene (trial 0 of the benchmark's base seed), planned by an independent
search (improved TCBiRRT, its own seed stream, a 30 s CPU budget) and certified by exact coal
distances along every edge (no point moving more than 1 cm between checks) and the closed-chain
residual. A draw without a witness is redrawn; the rejections are counted per family and reason
(:func:`rejection_summary`). The selection never looks at how the planners under test fare.

``optplan bench tcbirrt --generated N --seed S`` writes ``N`` fresh draws as TOML to
``OUT/generated/`` and runs the benchmark on them (one trial each), reported separately from the
fixed suite.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import OptionError
from ..scene import Obstacle, Scene
from .scene_witness import WITNESS_TIME_LIMIT, Witness, check_witness_planners, plan_witness, save_witness

__all__ = ["FAMILIES", "POOL", "GeneratedScene", "Rejection", "generate_scene", "generate_scenes", "feasibility",
           "scene_toml", "write_scenes", "family_summary", "rejection_summary"]

FAMILIES = ("wall", "bay", "corridor", "clutter", "truss", "overhang")
#: shipped scenes whose object, start/goal poses and end configurations the generated scenes reuse
POOL = ("hard_bay", "hard_window", "hard_corridor", "hard_flip", "hard_truss", "hard_clutter_dense",
        "ssps_scene1", "ssps_scene2", "ssps_scene3")


@dataclass(frozen=True)
class GeneratedScene:
    """A feasible draw: the scene, its family, the index of the draw, how many draws were rejected before
    it, the CPU seconds [s] spent on it, its witness (None when drawn without one; the first certified
    in the order of the witness planners) and the witness planners that certified it."""

    scene: Scene
    family: str
    index: int
    rejected: int
    seconds: float
    witness: Witness | None = None
    certified_by: tuple[str, ...] = ()


@dataclass(frozen=True)
class Rejection:
    """A rejected draw: its family, index, draw number and why (the check that failed)."""

    family: str
    index: int
    draw: int
    reason: str


def _box(name: str, size: Any, centre: Any, R: Any = None) -> Obstacle:
    R = np.eye(3) if R is None else np.asarray(R, float)
    sx, sy, sz = (float(x) for x in size)
    return Obstacle(name, "box", pin.SE3(R, np.asarray(centre, float)), size=(sx, sy, sz))


def _frame(n: np.ndarray) -> np.ndarray:
    """A rotation whose third column is the unit vector ``n``."""
    n = n / np.linalg.norm(n)
    t = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(t, n)
    e1 /= np.linalg.norm(e1)
    return np.column_stack([e1, np.cross(n, e1), n])


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    return np.asarray(pin.exp3(np.asarray(axis, float) / np.linalg.norm(axis) * angle))


def _half_extent(M: pin.SE3, half: np.ndarray, d: np.ndarray) -> float:
    """Half the extent along the unit vector ``d`` of a box of half edges ``half`` at pose ``M``."""
    return float(np.abs(M.rotation.T @ d) @ half)


def _wall(rng: np.random.Generator, s: pin.SE3, g: pin.SE3, half: np.ndarray) -> list[Obstacle]:
    u = g.translation - s.translation
    u /= np.linalg.norm(u)
    n = _rot(np.cross(u, rng.normal(size=3)), rng.uniform(0.0, math.radians(20))) @ u
    y = np.array([0.0, 1.0, 0.0])
    e1 = y - (y @ n) * n
    e1 = _rot(n, rng.uniform(-math.radians(15), math.radians(15))) @ (e1 / np.linalg.norm(e1))
    e2 = np.cross(n, e1)
    F = np.column_stack([e1, e2, n])
    c = 0.5 * (s.translation + g.translation) + e2 * rng.uniform(-0.3, 0.3) + e1 * rng.uniform(-0.1, 0.1)
    L, t = rng.uniform(3.0, 4.2), rng.uniform(0.08, 0.2)
    w, h = rng.uniform(3.1, 3.6), rng.uniform(0.95, 1.6)   # opening along e1 (the arms pass at its ends) and e2
    core = 1.8                                             # the wall between the arms, across the opening
    side = max((L - w) / 2, 0.2)
    out = [_box(f"wall_side_{k}", (side, L, t), c + e1 * sgn * (w / 2 + side / 2), F)
           for k, sgn in enumerate((-1, 1))]
    cap = (L - h) / 2
    out += [_box(f"wall_cap_{k}", (core, cap, t), c + e2 * sgn * (h / 2 + cap / 2), F)
            for k, sgn in enumerate((-1, 1))]
    return out


def _bay(rng: np.random.Generator, s: pin.SE3, g: pin.SE3, half: np.ndarray) -> list[Obstacle]:
    psi = rng.uniform(-math.radians(35), math.radians(35))
    a = np.array([math.cos(psi), math.sin(psi), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    b = np.cross(z, a)
    R = np.column_stack([a, b, z])
    ha, hb, hz = (_half_extent(g, half, v) for v in (a, b, z))
    cv, cb, t = rng.uniform(0.1, 0.3), rng.uniform(0.05, 0.2), 0.1
    d0 = max(2 * ha + 0.1, 0.9)
    depth = rng.uniform(d0, d0 + 0.7)
    width = 2 * hb + rng.uniform(-0.2, 0.4)
    p = g.translation
    back = p + a * (ha + cb + t / 2)
    mid = p + a * (ha + cb - depth / 2)
    return [_box("bay_back", (t, width, 2 * (hz + cv + t)), back, R),
            _box("bay_top", (depth, width, t), mid + z * (hz + cv + t / 2), R),
            _box("bay_bottom", (depth, width, t), mid - z * (hz + cv + t / 2), R)]


def _corridor(rng: np.random.Generator, s: pin.SE3, g: pin.SE3, half: np.ndarray) -> list[Obstacle]:
    w = 0.5 * (s.translation + g.translation) + np.array([rng.uniform(-0.8, 0.8), 0.0, rng.uniform(-0.3, 0.3)])
    out = []
    for k, (p0, p1, M) in enumerate(((s.translation, w, s), (w, g.translation, g))):
        d = p1 - p0
        length = float(np.linalg.norm(d))
        if length < 0.3:
            continue
        d /= length
        n = np.cross(d, np.array([0.0, 1.0, 0.0]))
        if np.linalg.norm(n) < 1e-6:
            continue
        n /= np.linalg.norm(n)
        R = np.column_stack([d, np.cross(n, d), n])
        gap = _half_extent(M, half, n) + rng.uniform(0.1, 0.3)
        c = 0.5 * (p0 + p1)
        for j, sgn in enumerate((-1, 1)):
            out.append(_box(f"corridor_{k}_{j}", (0.8 * length, 1.8, 0.08), c + sgn * (gap + 0.04) * n, R))
    return out


def _region(s: pin.SE3, g: pin.SE3, grow: float) -> tuple[np.ndarray, np.ndarray]:
    lo = np.minimum(s.translation, g.translation) - grow
    hi = np.maximum(s.translation, g.translation) + grow
    return lo, hi


def _clutter(rng: np.random.Generator, s: pin.SE3, g: pin.SE3, half: np.ndarray) -> list[Obstacle]:
    lo, hi = _region(s, g, 0.8)
    out = []
    for k in range(int(rng.integers(4, 17))):
        M = pin.SE3(np.asarray(pin.exp3(rng.normal(0.0, 1.5, 3))), rng.uniform(lo, hi))
        kind = rng.choice(["box", "sphere", "capsule"])
        if kind == "box":
            out.append(_box(f"clutter_{k}", rng.uniform(0.1, 0.5, 3), M.translation, M.rotation))
        elif kind == "sphere":
            out.append(Obstacle(f"clutter_{k}", "sphere", M, radius=float(rng.uniform(0.05, 0.25))))
        else:
            out.append(Obstacle(f"clutter_{k}", "capsule", M, radius=float(rng.uniform(0.05, 0.15)),
                                length=float(rng.uniform(0.1, 0.5))))
    return out


def _truss(rng: np.random.Generator, s: pin.SE3, g: pin.SE3, half: np.ndarray) -> list[Obstacle]:
    lo, hi = _region(s, g, 0.4)
    out = []
    for k in range(int(rng.integers(2, 6))):
        yaw, pitch = rng.uniform(-math.pi, math.pi), rng.uniform(-math.radians(20), math.radians(20))
        R = np.asarray(pin.rpy.rpyToMatrix(0.0, pitch, yaw))
        t = rng.uniform(0.12, 0.25)
        out.append(_box(f"truss_{k}", (rng.uniform(2.5, 4.0), t, t), rng.uniform(lo, hi), R))
    return out


def _overhang(rng: np.random.Generator, s: pin.SE3, g: pin.SE3, half: np.ndarray) -> list[Obstacle]:
    z = np.array([0.0, 0.0, 1.0])
    hz = _half_extent(s, half, z)
    c = s.translation + z * (hz + rng.uniform(0.15, 0.4) + 0.05) + np.array([rng.uniform(-0.8, 0.8), 0.0, 0.0])
    out = [_box("overhang", (rng.uniform(1.2, 2.0), rng.uniform(2.5, 3.5), 0.1), c)]
    if rng.random() < 0.5:
        p = 0.5 * (s.translation + g.translation) + np.array([rng.uniform(0.6, 1.2), rng.uniform(-0.5, 0.5), 0.0])
        out.append(Obstacle("post", "capsule", pin.SE3(np.eye(3), p), radius=float(rng.uniform(0.1, 0.2)),
                            length=float(rng.uniform(1.0, 2.5))))
    return out


_BUILDERS = {"wall": _wall, "bay": _bay, "corridor": _corridor, "clutter": _clutter, "truss": _truss,
             "overhang": _overhang}


def generate_scene(family: str, rng: np.random.Generator, name: str | None = None, robot: Any = None) -> Scene:
    """One random draw of ``family`` (not checked: see :func:`feasibility`). With ``robot``, the
    obstacles make room for it at the end configurations (:func:`_clear_ends`)."""
    if family not in _BUILDERS:
        raise ValueError(f"scene family: expected one of {FAMILIES}, got {family!r}")
    base = Scene.load(str(rng.choice(POOL)))
    assert base.object is not None and base.start is not None and base.goal is not None   # the pool's scenes have them
    s, g, extra = base.start, base.goal, dict(base.extra)
    if rng.random() < 0.5:   # the way back
        s, g = g, s
        extra["q_start"], extra["q_goal"] = base.extra["q_goal"], base.extra["q_start"]
    half = np.asarray(base.object.size, float) / 2
    obstacles = tuple(_BUILDERS[family](rng, s, g, half))
    extra["generated_from"] = base.name
    extra["family"] = family
    scene = replace(base, name=name or f"gen_{family}", obstacles=obstacles, start=s, goal=g, extra=extra)
    return _clear_ends(scene, family, robot) if robot is not None else scene


#: shifts [m] along the way from start to goal tried for a structured family's obstacles (all together)
#: until neither end configuration touches them
SHIFTS = (0.0, 0.15, -0.15, 0.3, -0.3, 0.45, -0.45, 0.6, -0.6)


def _end_configurations(robot: Any, scene: Scene) -> list[np.ndarray]:
    from ..trials import TrialGenerator

    gen = TrialGenerator(robot, replace(scene, obstacles=()))
    return [q for q in (gen.q_nominal["q_start"], gen.q_nominal["q_goal"]) if q is not None]


def _clear_ends(scene: Scene, family: str, robot: Any) -> Scene:
    """Make room for the robot at the two end configurations: clutter and truss drop the obstacles
    that touch it there; the other families shift their obstacles together along the way (the first
    shift of :data:`SHIFTS` that clears both ends; unchanged when none does)."""
    from ..planners.validity import ValidityChecker

    assert scene.start is not None and scene.goal is not None
    qs = _end_configurations(robot, scene)

    def touched(sc: Scene) -> set[str]:
        ck = ValidityChecker(robot, sc)
        names: set[str] = set()
        for q in qs:
            for a, b in ck.colliding_pairs(q, "held"):
                names.update(n[len("obstacle/"):] for n in (a, b) if n.startswith("obstacle/"))
        return names

    if family in ("clutter", "truss"):
        bad = touched(scene)
        return replace(scene, obstacles=tuple(o for o in scene.obstacles if o.name not in bad))
    u = scene.goal.translation - scene.start.translation
    u /= np.linalg.norm(u)
    for shift in SHIFTS:
        M = pin.SE3(np.eye(3), u * shift)
        sc = replace(scene, obstacles=tuple(replace(o, placement=M * o.placement) for o in scene.obstacles))
        if not touched(sc):
            return sc
    return scene


def feasibility(robot: Any, scene: Scene, *, seed: int = 0, lead_iterations: int = 14_000,
                lead_time: float = 10.0) -> str | None:
    """None when ``scene`` passes the necessary conditions (see the module docstring), else why not.

    The object-only lead path gets ``lead_iterations`` iterations of its search [count] (so that a seed draws the
    same scenes on any machine and load: 14,000 is the lead path's median rate on the suite, 14,108 iterations per
    CPU second, times the 1 s this check had before; see docs/decisions/0024-sub-search-work-budgets.md) and
    ``lead_time`` CPU seconds [s] as a backstop that does not bind in normal runs."""
    from ..planners.base import Deadline
    from ..planners.task_sampling import ObjectPoseFilter, object_lead_path
    from ..planners.tcbirrt_options import TCBiRRTOptions, reach_scaled_workspace
    from ..planners.validity import ValidityChecker
    from ..trials import TrialGenerator

    if not (isinstance(lead_iterations, int) and not isinstance(lead_iterations, bool) and lead_iterations >= 1):
        raise OptionError(f"lead_iterations: expected an int >= 1, got {lead_iterations!r}")
    assert scene.object is not None and scene.start is not None and scene.goal is not None
    if not scene.obstacles:
        return "no obstacles (all removed to clear the end configurations)"
    ck = ValidityChecker(robot, scene)
    gen = TrialGenerator(robot, scene)
    for key in ("q_start", "q_goal"):
        q = gen.q_nominal[key]
        if q is None or not ck.is_valid(q):
            return f"{key} in collision"
    try:
        gen.generate(0, seed)
    except RuntimeError:
        return "no trial (start/goal IK)"
    filt = ObjectPoseFilter(robot, scene)
    lo, hi, _ = reach_scaled_workspace(robot, TCBiRRTOptions())
    xs = np.concatenate([scene.start.translation, pin.rpy.matrixToRpy(scene.start.rotation)])
    xg = np.concatenate([scene.goal.translation, pin.rpy.matrixToRpy(scene.goal.rotation)])
    budget = Deadline(lead_time, "cpu").sub(lead_time, work=lead_iterations)
    path = object_lead_path(filt, xs, xg, lo, hi, np.random.default_rng(seed), budget)
    return None if path is not None else "no path of the object alone"


def generate_scenes(robot: Any, n: int, seed: int, families: tuple[str, ...] = FAMILIES,
                    max_draws: int = 20, *, trial_seed: int | None = None,
                    witness_time: float = WITNESS_TIME_LIMIT,
                    rejections: list[Rejection] | None = None,
                    witnesses: tuple[str, ...] | str = ("tcbirrt",)) -> list[GeneratedScene]:
    """``n`` feasible draws, the families in turn, from ``numpy.random.default_rng(seed)``; each family
    draw is redrawn up to ``max_draws`` times until it passes :func:`feasibility` and has a certified
    witness for trial 0 of base seed ``trial_seed`` (default ``seed``: the benchmark's query) found
    within ``witness_time`` CPU seconds [s] per witness search (0: no witness, the object-only check
    alone); an index whose every draw fails is skipped. Each rejected draw is appended to ``rejections``.

    ``witnesses`` names the witness searches (:data:`.scene_witness.WITNESS_PLANNERS`, e.g.
    ``("cbirrt2", "tcbirrt")``): every one runs on each draw, with the same witness seed, and a draw is
    kept when any certifies it; :attr:`GeneratedScene.certified_by` lists which did. The random stream
    of the draws does not depend on this choice."""
    for f in families:
        if f not in _BUILDERS:
            raise ValueError(f"scene family: expected one of {FAMILIES}, got {f!r}")
    if not (isinstance(witness_time, (int, float)) and math.isfinite(witness_time) and witness_time >= 0):
        raise OptionError(f"witness_time: expected a number of CPU seconds >= 0, got {witness_time!r}")
    wplanners = check_witness_planners(witnesses)
    tseed = seed if trial_seed is None else trial_seed
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        fam = families[i % len(families)]
        t0 = time.process_time()
        for k in range(max_draws):
            sc = generate_scene(fam, rng, f"gen_{seed}_{i:03d}_{fam}", robot)
            why = feasibility(robot, sc, seed=int(rng.integers(2**31)))
            witness_seed = int(rng.integers(2**31))   # drawn always: the stream does not depend on the outcomes
            w, by = None, []
            if why is None and witness_time > 0:
                whys = []
                for wp in wplanners:
                    wk, why_k = plan_witness(robot, sc, tseed, witness_seed, witness_time, planner=wp)
                    if wk is not None:
                        w = wk if w is None else w
                        by.append(wp)
                    else:
                        whys.append(why_k if len(wplanners) == 1 else f"{why_k} ({wp})")
                why = None if by else "; ".join(str(x) for x in whys)
            if why is None:
                out.append(GeneratedScene(sc, fam, i, k, time.process_time() - t0, w, tuple(by)))
                break
            if rejections is not None:
                rejections.append(Rejection(fam, i, k, why))
    return out


def _reason_kind(reason: str) -> str:
    return "no witness" if reason.startswith("witness") else reason.split(":")[0]


def rejection_summary(kept: list[GeneratedScene], rejections: list[Rejection]) -> str:
    """Per family: scenes kept, draws rejected (by reason) and indices skipped (every draw rejected)."""
    lines = [f"{'family':9s} {'kept':>5s} {'rejected draws':>15s} {'skipped':>8s}  reasons"]
    for fam in FAMILIES:
        rr = [r for r in rejections if r.family == fam]
        kk = [g for g in kept if g.family == fam]
        if not rr and not kk:
            continue
        kept_idx = {g.index for g in kk}
        skipped = len({r.index for r in rr} - kept_idx)
        reasons: dict[str, int] = {}
        for r in rr:
            reasons[_reason_kind(r.reason)] = reasons.get(_reason_kind(r.reason), 0) + 1
        text = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1]))
        lines.append(f"{fam:9s} {len(kk):5d} {len(rr):15d} {skipped:8d}  {text}")
    return "\n".join(lines)


def _fmt(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)


def _pose_toml(M: pin.SE3) -> str:
    return f"xyz = {_fmt(list(M.translation))}\nrpy = {_fmt(list(pin.rpy.matrixToRpy(M.rotation)))}\n"


def scene_toml(scene: Scene) -> str:
    """``scene`` as a scene TOML (angles in radians) that :meth:`Scene.load` reads back."""
    assert scene.object is not None and scene.start is not None and scene.goal is not None
    ex = dict(scene.extra)
    lines = [f"# generated by optplan.bench.scenegen (family {ex.get('family')}, from {ex.get('generated_from')})",
             f"name = {_fmt(scene.name)}", f"robot = {_fmt(scene.robot)}", 'angle_unit = "rad"', "", "[object]",
             f"size = {_fmt(list(scene.object.size))}",
             "grasps = { " + ", ".join(f"{arm} = {{ xyz = {_fmt(list(G.translation))}, rpy = "
                                       f"{_fmt(list(pin.rpy.matrixToRpy(G.rotation)))} }}"
                                       for arm, G in scene.object.grasps.items()) + " }",
             f"exclude_links = {_fmt(list(scene.object.exclude_links))}", "", "[start]", _pose_toml(scene.start),
             "[goal]", _pose_toml(scene.goal)]
    for o in scene.obstacles:
        lines += ["[[obstacles]]", f"name = {_fmt(o.name)}", f"shape = {_fmt(o.shape)}"]
        if o.shape == "box":
            lines.append(f"size = {_fmt(list(o.size or ()))}")
        else:
            lines.append(f"radius = {_fmt(o.radius)}")
            if o.shape == "capsule":
                lines.append(f"length = {_fmt(o.length)}")
        lines += [_pose_toml(o.placement)]
    unit = math.pi / 180.0 if ex.get("q_unit") == "deg" else 1.0
    lines += ["[extra]"]
    for k, v in ex.items():
        if k in ("q_start", "q_goal"):
            v = [float(x) * unit for x in v]
        elif k == "q_unit":
            v = "rad"
        lines.append(f"{k} = {_fmt(v)}")
    return "\n".join(lines) + "\n"


def write_scenes(scenes: list[GeneratedScene], directory: str | Path) -> list[str]:
    """Write each draw as ``directory/<name>.toml`` (its witness, if any, as ``<name>.witness.npz``; the
    witness planners that certified it as ``certified_by`` in its ``[extra]``); the paths of the TOML
    files, in order."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for gs in scenes:
        p = d / f"{gs.scene.name}.toml"
        sc = replace(gs.scene, extra={**gs.scene.extra, "certified_by": list(gs.certified_by)}) if gs.certified_by else gs.scene
        p.write_text(scene_toml(sc), encoding="utf-8")
        if gs.witness is not None:
            save_witness(gs.witness, d / f"{gs.scene.name}.witness.npz")
        paths.append(str(p))
    return paths


def family_of(scene: str) -> str:
    """The family of a generated scene from its name or path (``gen_<seed>_<index>_<family>``)."""
    stem = Path(str(scene)).stem
    return stem.rsplit("_", 1)[-1] if stem.startswith("gen_") else "fixed"


def family_summary(rows: list[dict[str, Any]], certified_by: dict[str, tuple[str, ...]] | None = None) -> str:
    """Per planner and family: successes / queries and the median CPU seconds of all queries (a failed
    query counts its time limit), then all families together. With ``certified_by`` (scene name → the
    witness planners that certified it, :attr:`GeneratedScene.certified_by`) the same again over the
    scenes each witness certified (column ``witness``; ``any``: every scene)."""
    by = {Path(str(k)).stem: tuple(v) for k, v in (certified_by or {}).items()}
    witnesses = ["any", *dict.fromkeys(w for v in by.values() for w in v)] if by else ["any"]
    lines = [f"{'planner':34s} {'witness':8s} {'family':9s} {'success':>9s} {'rate':>5s} {'median CPU s':>13s}"]
    for pl in dict.fromkeys(r["planner"] for r in rows):
        for wit in witnesses:
            mine = [r for r in rows if r["planner"] == pl and (wit == "any" or wit in by.get(Path(str(r["scene"])).stem, ()))]
            for fam in (*FAMILIES, "all"):
                rr = [r for r in mine if fam == "all" or family_of(r["scene"]) == fam]
                if not rr:
                    continue
                ok = sum(bool(r["success"]) for r in rr)
                cpu = [float(r["cpu_time_s"]) if r["success"] else float(r["time_limit_s"]) for r in rr]
                lines.append(f"{pl:34s} {wit:8s} {fam:9s} {ok:4d}/{len(rr):<4d} {ok / len(rr):5.2f} {np.median(cpu):13.3f}")
    return "\n".join(lines)
