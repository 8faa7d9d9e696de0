"""`CollisionAvoidance` for a free-floating robot on the B-spline kernel core of `OptProblem`.

The rows are the fixed-base segment NLP's separating planes (decision 0003/0012: normals fixed at
coal's witness normal along the first guess, the pairs that guess brings within ``activation``,
margins relaxed next to the given boundary configurations, box vertices pruned), with each body's
world placement the base pose times the joint forward kinematics:

    x_world = R_w(xi) · (p_f(q) + R_f(q) v − c(q)) + c0,   R_w = R(base0) · R(xi)

where ``xi`` is the base attitude relative to the start at the knot (a decision variable of the
core), ``c(q)`` the centre of mass in the base frame and ``c0`` the fixed world centre of mass
(zero momentum: the base position follows from the joints and the attitude, as
:func:`~optplan.problem.floating_collision.base_placements` computes it).

* A pair with an obstacle (fixed in the world) gets a *world* plane: kernel
  ``f([q; xi; base0; c0; n; s]) = s − n·x_world − r`` with the obstacle's support value ``s``
  along the world normal ``n``. It has rows at every active knot but the first (the start
  configuration and base are given); the last knot's base attitude is free, so it keeps its rows.
* A pair of two robot bodies (or the held object and a body) does not depend on the base pose:
  its plane is fixed in the *base* frame (the world witness normal turned into the base frame at
  the guess) and the fixed-base pair kernel of :class:`~optplan.problem.kernels.KernelCache`
  (base-frame kinematics for a floating robot) is used as it is; a side on the base body is
  static in the base frame. Knots whose joints are given carry no rows.

The exact Jacobian and Hessian come from the kernels (:meth:`SplineCore.kernel_set`)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ..model.symbolic import quat_to_matrix
from .collision_term import CollisionAvoidance, _box_vertices
from .frame_terms import ClosedChain
from .kernels import geometry_points
from .plane_rows import SPLINE_ACTIVATION
from .spline_collision import CollisionItem
from .terms import NumericTrajectory

__all__ = ["FloatingCollisionItem", "plan_floating_collision", "world_pair_slots", "full_configurations"]

#: A moving box keeps the rows of the vertices within this distance of its leading vertex along a
#: plane's normal at some knot (as the segment NLP's ``vertex_window``) [m].
VERTEX_WINDOW = 0.5


@dataclass
class FloatingCollisionItem(CollisionItem):
    """A :class:`CollisionItem` of a floating robot; ``world``: the plane is fixed in the world
    (a pair with an obstacle; kernel input ``[q; xi; base0; c0; n; s]``), else in the base frame
    (kernel input ``[q; n; s]``)."""

    world: bool = False


def full_configurations(core: Any, Qk: np.ndarray, xi: np.ndarray, base0: pin.SE3, com0: np.ndarray) -> np.ndarray:
    """Pinocchio configurations ((N+1) × (7 + nj)) of the knots: base position [m] from the fixed
    centre of mass ``com0``, world base quaternion ``base0 · xi``, joints ``Qk`` [rad]."""

    quats, pos = base_placements(core, Qk, xi, base0, com0)
    return np.hstack([pos, quats, Qk])


def _side(col: Any, robot: Any, kind: str, idx: int, holder: str | None,
          fixed: frozenset[int]) -> tuple[str, int | None, np.ndarray, float]:
    """One side of a pair: ``(where, frame, points 3 × m, radius)`` with ``where`` "world" (an
    obstacle: world points, frame None), "base" (on the base body: no free joint moves it in the
    base frame) or "moving" (points in frame ``frame``)."""
    if kind == "obstacle":
        o = col.checker.obstacles[idx]
        if o.shape == "box":
            V, r = np.array(_box_vertices(np.asarray(o.size) / 2)).T, 0.0
        elif o.shape == "sphere":
            V, r = np.zeros((3, 1)), float(o.radius)
        else:
            V, r = np.array([[0, 0, -o.length / 2], [0, 0, o.length / 2]]).T, float(o.radius)
        M = o.placement
        return "world", None, M.rotation @ V + M.translation[:, None], r
    if kind == "object":
        assert holder is not None  # an object pair exists only with a held object
        V = np.array(_box_vertices(np.asarray(col.checker.object.size) / 2)).T
        G = col.grasp_inv
        fid, V, r = robot.arm(holder).ee_frame_id, G.rotation @ V + G.translation[:, None], 0.0
    else:
        spec = col.robot_shape.get(idx)
        if spec is None:
            fid, V, r = geometry_points(robot, idx)
        else:
            fid, shape, Mbox = spec
            from ..geometry import distance as D

            if isinstance(shape, D.Box):
                V, r = np.array([Mbox.act(v) for v in _box_vertices(np.asarray(shape.half_extents))]).T, 0.0
            elif isinstance(shape, D.Sphere):
                V, r = np.asarray(shape.center, float).reshape(3, 1), float(shape.radius)
            else:
                V, r = np.array([shape.a, shape.b], float).T, float(shape.radius)
    where = "base" if col.free_joints_of(robot, kind, idx, fixed) == set() else "moving"   # on the base body or not
    return where, int(fid), V, r


def _frame_points(robot: Any, data: Any, fid: int, V: np.ndarray) -> np.ndarray:
    M = data.oMf[fid]
    return M.rotation @ V + M.translation[:, None]


def _world_kernel(core: Any, fid: int, V: np.ndarray, r: float) -> ca.Function:
    """``f([q; xi; base0; c0; n; s]) = s − n·x_i − r`` for the world points ``x_i`` of the points
    ``V`` (3 × m) of frame ``fid`` (module docstring), cached per robot and point set."""
    kc, sym, nj = core.kc, core.sym, core.nj
    V = np.ascontiguousarray(V, float)

    def build(name: str) -> ca.Function:
        xi, b0, c0 = ca.SX.sym("xi", 4), ca.SX.sym("b0", 4), ca.SX.sym("c0", 3)
        n, s = ca.SX.sym("n", 3), ca.SX.sym("s")
        Rf, pf = kc.frame(fid)
        Rw = quat_to_matrix(b0) @ quat_to_matrix(xi)
        Xb = Rf @ ca.DM(V) + ca.repmat(pf - sym._com_base(), 1, V.shape[1])
        Xw = Rw @ Xb + ca.repmat(c0, 1, V.shape[1])
        z = ca.vertcat(kc._q, xi, b0, c0, n, s)
        assert z.shape[0] == nj + 15
        return ca.Function(name, [z], [(s - n.T @ Xw - r).T])

    return kc._get(("floating_world_pair", int(fid), V.shape, V.tobytes(), float(r)), build)


def _prune(V: np.ndarray, placed: list[np.ndarray], normals: np.ndarray, sign: float) -> np.ndarray:
    """Columns of ``V`` within :data:`VERTEX_WINDOW` of the leading point along ``sign · n`` at
    some knot (``placed[t]``: the points at knot t in the normal's frame)."""
    if V.shape[1] <= 2:
        return np.ones(V.shape[1], bool)
    keep = np.zeros(V.shape[1], bool)
    for t, X in enumerate(placed):
        proj = sign * normals[:, t] @ X
        keep |= proj >= proj.max() - VERTEX_WINDOW
    return keep


def plan_floating_collision(prob: Any, core: Any, term: CollisionAvoidance, x: np.ndarray, base0: pin.SE3,
                            com0: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                            boost: dict[tuple[Any, int], float] | None = None
                            ) -> tuple[list[FloatingCollisionItem], Any]:
    """The active pairs of a floating robot along the guess ``x`` (core variables: the joint
    B-spline and the base attitude at the knots) and their kernels; also the term's
    :class:`~optplan.problem.collision_term.CollisionModel` (checker, active and constant pairs,
    relaxed margins). ``boost``: (pair, knot) → margin added there [m] (a pair with a boost is
    active at that knot)."""
    robot, N = prob.robot, core.N
    boost = dict(boost or {})
    Qk = core.M["q"] @ core.control_points(x)
    pinned = prob._pinned_q()
    for k, q in pinned.items():
        Qk[k] = q
    xi = core.knot_xi(x)
    Qf = full_configurations(core, Qk, xi, base0, com0)
    quats = Qf[:, 3:7]
    default = CollisionAvoidance.__dataclass_fields__["activation"].default
    if term.activation == default:   # the segment NLP's activation (decision 0012), as spline_collision
        term = dataclasses.replace(term, activation=SPLINE_ACTIVATION)
    col = term.model(robot)
    traj = NumericTrajectory(robot, Qk, Qk, Qk, Qk[:-1], prob.duration, base_quat=quats, com0=com0)
    active = col.activate(robot, traj)
    for pair, k in boost:   # a boosted row is always constrained
        if pair not in col.checker.pair_index or not 0 <= k <= N:
            continue
        ks0 = col.active_knots.get(pair, [])
        if pair not in active:
            active.append(pair)
        if ks0 is not None and k not in ks0:
            col.active_knots[pair] = sorted([*ks0, k])
    fixed = frozenset(np.flatnonzero(np.isfinite(lower) & (lower == upper)).tolist())
    cc = next((h.term for h in prob._handles if h.role == "constraint" and isinstance(h.term, ClosedChain)), None)
    rigid = [cc.arm_a, cc.arm_b] if cc is not None else [a for a in (col.checker.object_arm,) if a is not None]
    const = [p for p in active if col.is_constant(robot, p, fixed, rigid)]
    active = [p for p in active if p not in const]
    col.active_pairs, col.constant_pairs = active, const
    # margins: halved distance within `window` knots of a knot where the (collision-free) guess is
    # closer than the margin, as the segment NLP's relax_to_guess; a colliding guess keeps the margin
    margin, w = float(term.margin), int(term.window)
    D0 = col._init_dist
    assert D0 is not None  # set by activate
    relaxed: dict[tuple[Any, int], float] = {}
    for p in active:
        i = col.checker.pair_index[p]
        for kp in range(N + 1):
            d = float(D0[kp, i])
            if d < margin and (kp in pinned or d >= 0.0):
                for k in range(max(0, kp - w), min(N, kp + w) + 1):
                    relaxed[(p, k)] = min(min(margin, 0.5 * d), relaxed.get((p, k), np.inf))
    col.relaxed = relaxed
    holder = col.checker.object_arm
    data = robot.model.createData()
    datas = []
    for k in range(N + 1):
        d = robot.model.createData()
        pin.framesForwardKinematics(robot.model, d, robot.configuration(Qk[k]))   # base frame (base at identity)
        datas.append(d)
    Rb = [pin.Quaternion(qq[3], *qq[:3]).normalized().toRotationMatrix() for qq in quats]
    items: list[FloatingCollisionItem] = []
    kc, nj = core.kc, core.nj
    for pair in active:
        ka, kb = col.kinds(pair)
        sa = _side(col, robot, ka, pair.a, holder, fixed)
        sb = _side(col, robot, kb, pair.b, holder, fixed)
        world = "world" in (sa[0], sb[0])
        if world:   # the robot's side moves in the world with the base
            flip = sa[0] == "world"
            if sb[0] == sa[0]:
                continue
        else:
            flip = sa[0] == "base"
            if sb[0] == sa[0] == "base":
                continue   # both on the base body: constant distance
        mov, other = (sb, sa) if flip else (sa, sb)
        if other[0] == "base":   # static in the base frame: its base-frame points
            assert other[1] is not None  # a robot side has its frame
            other = ("base", None, _frame_points(robot, datas[0], other[1], other[2]), other[3])
        ks = [k for k in col.knots_of(pair, N) if k != 0 and (world or k not in pinned)]
        if not ks:
            continue
        idx = col.checker.pair_index[pair]
        K = len(ks)
        Nrm, off = np.zeros((3, K)), np.zeros(K)
        for t, k in enumerate(ks):
            nb = col.checker.witness_planes(Qf[k], [idx])[0]
            n, b = (-nb[:3], -nb[3]) if flip else (nb[:3], nb[3])
            if not world:   # into the base frame: n·(R y + t) = b
                n, b = Rb[k].T @ n, b - n @ Qf[k, :3]
            Nrm[:, t], off[t] = n, b
        fid, V, r = mov[1], mov[2], mov[3]
        assert fid is not None
        if world:
            placed = [Rb[k] @ (_frame_points(robot, datas[k], fid, V)
                               - pin.centerOfMass(robot.model, data, robot.configuration(Qk[k]))[:, None])
                      for k in ks]
        else:
            placed = [_frame_points(robot, datas[k], fid, V) for k in ks]
        V = V[:, _prune(V, placed, Nrm, 1.0)]
        static = other[0] != "moving"
        if static:
            Y, rb = other[2], other[3]
            off = np.min(Nrm.T @ Y, axis=1) - rb   # the static side's support along each normal
        margins = np.array([relaxed.get((pair, k), margin) + boost.get((pair, k), 0.0) for k in ks])
        name = f"collision:{pair.name_a}|{pair.name_b}"
        if world:
            fn = _world_kernel(core, fid, V, r)
            items.append(FloatingCollisionItem(name, fn, ks, Nrm, off, margins, V.shape[1], True, world=True))
            continue
        if static:
            pf = kc.pair(fid, V, r, None, np.zeros((3, 0)), 0.0)
            nrow = V.shape[1]
        else:
            fb, Vb, rbb = other[1], other[2], other[3]
            assert fb is not None
            Vb = Vb[:, _prune(Vb, [_frame_points(robot, datas[k], fb, Vb) for k in ks], Nrm, -1.0)]
            pf = kc.pair(fid, V, r, fb, Vb, rbb)
            nrow = V.shape[1] + Vb.shape[1]

        def build(nm: str, fn: ca.Function = pf) -> ca.Function:
            z = ca.SX.sym("z", nj + 4)
            return ca.Function(nm, [z], [fn(z[:nj], z[nj:nj + 3], z[nj + 3])])

        local = kc._get(("local_pair", pf.name()), build)
        items.append(FloatingCollisionItem(name, local, ks, Nrm, off, margins, nrow, static, world=False))
    return items, col


def world_pair_slots(core: Any, fam: Any) -> tuple[np.ndarray, np.ndarray]:
    """Template and slots of a world-plane kernel ``f([q; xi; base0; c0; n; s])`` at its knots
    (q = (P_k + 4 P_k+1 + P_k+2)/6; the rest are slots of ``[x; p]`` as they are)."""
    nj, nx = core.nj, core.nx
    it, po = fam.data["item"], fam.data["p_off"]
    K = len(fam.points)
    tm = [(j, a * nj + j, w) for j in range(nj) for a, w in enumerate((1 / 6, 4 / 6, 1 / 6))]
    tm += [(nj + c, 3 * nj + c, 1.0) for c in range(15)]
    rows = []
    for t, k in enumerate(fam.points):
        n = nx + core.p_col + po + 3 * t + np.arange(3)
        s = nx + core.p_col + po + 3 * K + t
        assert it.static
        rows.append(np.concatenate([core.slot_P(k), core.slot_P(k + 1), core.slot_P(k + 2), core.slot_xi(k),
                                    nx + core.p_b0 + np.arange(4), nx + core.p_c0 + np.arange(3), n, [s]]))
    return np.array(tm, float), np.array(rows, int)


def base_placements(core: Any, Q: np.ndarray, xi: np.ndarray, base0: pin.SE3,
                    com0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World base quaternions ((N+1) × 4, x y z w) and positions [m] with the centre of mass at
    ``com0``: the attitude R0 · R(xi) of every knot at once (the quaternion product b0 ⊗ xi, with
    the sign Pinocchio's conversion of the matrix gives: w > 0 when the trace is > 0, else the
    component of the largest diagonal entry > 0)."""
    model, data = core.robot.model, core.robot.data
    xi = np.asarray(xi, float)
    bx, by, bz, bw = pin.Quaternion(base0.rotation).coeffs()
    left = np.array([[bw, -bz, by, bx], [bz, bw, -bx, by], [-by, bx, bw, bz], [-bx, -by, -bz, bw]])
    quats = (xi / np.linalg.norm(xi, axis=1, keepdims=True)) @ left.T
    n = len(quats)
    lead = np.where(4.0 * quats[:, 3] ** 2 > 1.0, 3, np.argmax(np.abs(quats[:, :3]), axis=1))
    quats[quats[np.arange(n), lead] < 0] *= -1.0
    full = np.zeros(model.nq)
    full[6] = 1.0
    c = np.empty((n, 3))
    for k, qk in enumerate(np.asarray(Q, float)):
        full[7:] = qk
        c[k] = pin.centerOfMass(model, data, full)
    # R c by the quaternion: c + w t + v × t with t = 2 v × c
    v = quats[:, :3]
    t = 2.0 * np.cross(v, c)
    return quats, np.asarray(com0, float) - (c + quats[:, 3:] * t + np.cross(v, t))
