"""Attitude steering of a free-floating robot holding an object: closed loops of the held object.

With zero momentum the base's motion along a joint path is left-invariant and reversible: a path
moves the base by a displacement ``D`` (an SE(3) element in the base frame) that depends on the
joint path only, and the same path traversed backwards moves it by ``D⁻¹``. A CLOSED joint loop
(joints back where they started) therefore turns the base by its holonomy ``D`` and puts the joints
back where they were; with the centre of mass fixed the base position follows from the attitude.
Repeating a loop ``k`` times turns the base by ``Dᵏ``.

:class:`AttitudeSteerer` builds such loops with both hands holding the object: the object moves in
the base frame along a triangle through two random via poses (path IK, each waypoint on the closed
chain), and a self-motion join (the object held still) brings the joints back exactly to the loop's
start. It composes loops greedily: each round it takes, among a pool of loops (new random ones added
every round), the loop, direction and repetition count whose product brings the accumulated
rotation nearest the wanted one, keeps it when that is nearer and every repetition is collision-free
with the base where momentum puts it. A loop of 0.2 m / 0.3 rad turns the ``eba_ffsr`` base by a
few mrad (its base is 510 kg, each arm ≈ 42 kg): tens of loops turn it by 0.05 rad.

The steering is local and not exact: it stops within ``tol_rad`` of the wanted rotation, or when
no loop brings it nearer (then it returns what it reached, and the caller decides).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import OptionError
from ..model.robot import RobotModel
from .base import Deadline
from .floating_carry import FloatingCarryPlanner, integrate_edge
from .task_space import interpolate_task
from .validity import ValidityChecker

__all__ = ["SteerOptions", "SteerResult", "AttitudeSteerer", "path_displacement", "left_multiply"]


@dataclass(frozen=True)
class SteerOptions:
    """Options of :class:`AttitudeSteerer`."""

    #: range of a via pose's offset from the loop's start pose, per axis (object, base frame) [m].
    loop_m: float = 0.2
    #: range of a via pose's rotation offset, per exponential coordinate [rad].
    loop_rad: float = 0.3
    #: new random loops tried per round [count].
    new_loops: int = 4
    #: most repetitions of one loop in one round [count].
    max_repeat: int = 12
    #: most rounds (a round adds one loop, repeated) [count].
    max_rounds: int = 30
    #: the steering stops within this angle of the wanted rotation [rad].
    tol_rad: float = 2e-3
    #: largest joint change between consecutive waypoints of a loop [rad].
    max_joint_step: float = 0.3
    #: joint step of the self-motion join that closes a loop [rad].
    join_step_rad: float = 0.05
    #: most rounds of scaled loops for the small rotation left after the whole loops [count].
    refine_rounds: int = 8
    #: smallest clearance of every checked sample of a loop [m]. A kept manoeuvre runs between the
    #: checked samples and off the planner's straight edges (put back on the closed chain), where
    #: the clearance may dip below the samples' by micrometres: this margin keeps it clear. 0: none.
    clearance_m: float = 1e-3
    #: size of the probe loops of :meth:`AttitudeSteerer.steer_small` relative to ``loop_m`` /
    #: ``loop_rad`` [1] (a loop's holonomy grows with the square of its size: the probes are measured,
    #: not kept, and the loops kept are scaled from them).
    probe_scale: float = 0.3
    #: most probe loops drawn by :meth:`AttitudeSteerer.steer_small` [count].
    max_probes: int = 16

    def __post_init__(self) -> None:
        for name in ("loop_m", "loop_rad", "tol_rad", "max_joint_step", "join_step_rad"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise OptionError(f"SteerOptions.{name}: expected a positive finite number, got {v!r}")
        if not (isinstance(self.probe_scale, (int, float)) and 0 < self.probe_scale <= 1):
            raise OptionError(f"SteerOptions.probe_scale: expected a number in (0, 1], got {self.probe_scale!r}")
        for name in ("new_loops", "max_repeat", "max_rounds", "refine_rounds", "max_probes"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise OptionError(f"SteerOptions.{name}: expected an integer ≥ 1, got {v!r}")
        if not (isinstance(self.clearance_m, (int, float)) and math.isfinite(self.clearance_m) and self.clearance_m >= 0):
            raise OptionError(f"SteerOptions.clearance_m: expected a number ≥ 0 [m], got {self.clearance_m!r}")


@dataclass
class SteerResult:
    """The manoeuvre: ``joints`` the waypoints after the start (the last one equals the start's
    joints), ``bases`` the base pose after each; ``rotation`` the base rotation it makes in the
    base frame (``R_start⁻¹ R_end``); ``error_rad`` the angle left to the wanted rotation;
    ``loops`` loop traversals used; ``rows`` every collision sample (nq) after the start with the
    base relative to the start's (the manoeuvre from the identity: from any other base ``B`` the
    same samples are ``B`` times these, by left-invariance)."""

    joints: list[np.ndarray]
    bases: list[pin.SE3]
    rotation: np.ndarray
    error_rad: float
    loops: int
    rows: np.ndarray
    #: the base pose the manoeuvre starts from.
    start: pin.SE3


def path_displacement(robot: RobotModel, joints: list[np.ndarray],
                      check_step_rad: float) -> tuple[list[pin.SE3], np.ndarray]:
    """The base displacements (base frame, from the identity) at every waypoint of the joint path
    after the first (the last one is the path's displacement ``D``) and every sample row (nq) of its
    edges after the first point, the base integrated edge by edge
    (:func:`~optplan.planners.floating_carry.integrate_edge`)."""
    base, rows, out = pin.SE3.Identity(), [], []
    for qa, qb in zip(joints[:-1], joints[1:]):
        n = max(1, math.ceil(float(np.max(np.abs(qb - qa))) / check_step_rad))
        Q = integrate_edge(robot, base, qa, qb, n)
        rows.append(Q[1:])
        base = pin.XYZQUATToSE3(Q[-1, :7])
        out.append(base)
    return out, (np.vstack(rows) if rows else np.empty((0, robot.nq)))


def left_multiply(rows: np.ndarray, B: pin.SE3) -> np.ndarray:
    """The rows with their base poses left-multiplied by ``B`` (the same joint path from base ``B``)."""
    out = rows.copy()
    for i in range(len(rows)):
        out[i, :7] = pin.SE3ToXYZQUAT(B * pin.XYZQUATToSE3(rows[i, :7]))
    return out


@dataclass
class _Loop:
    joints: list[np.ndarray]   # q, ..., q
    X: list[pin.SE3]           # displacement at each waypoint after the first (forward)
    rows: np.ndarray           # its samples from the identity base (after the first point)
    xis: np.ndarray            # the via poses' offsets (2 × 6), before the scale
    scale: float               # the via poses are M·exp(scale·ξ)

    @property
    def D(self) -> pin.SE3:
        """The displacement of one forward traversal."""
        return self.X[-1]


class AttitudeSteerer:
    """Closed object loops that turn a free-floating base (module docstring). ``carry`` supplies the
    closed-chain IK (:meth:`~optplan.planners.floating_carry.FloatingCarryPlanner.hold`) and the
    collision-check step; ``validity`` checks each repetition with the base where momentum puts it
    (with ``options.clearance_m`` > 0: a checker of the same scene with that margin)."""

    def __init__(self, carry: FloatingCarryPlanner, validity: ValidityChecker, options: SteerOptions | None = None):
        self.carry, self.validity = carry, validity
        self.robot = carry.robot
        self.options = options or SteerOptions()
        self._margined: dict[float, ValidityChecker] = {float(validity.margin): validity}

    def _checker(self) -> ValidityChecker:
        """The collision checker with the margin ``options.clearance_m`` (built once per margin)."""
        m = float(self.options.clearance_m)
        if m not in self._margined:
            self._margined[m] = ValidityChecker(self.robot, self.carry.scene, margin=m)
        return self._margined[m]

    def _loop(self, q: np.ndarray, rng: np.random.Generator | None, xis: np.ndarray | None = None,
              scale: float = 1.0) -> _Loop | None:
        """A closed loop from ``q``: the object through the via poses ``M·exp(scale·ξ)`` (``xis``:
        the two ξ, default random) and back, then a self-motion join to ``q``; None when the IK
        fails or jumps."""
        o, co = self.options, self.carry.options
        M = self.carry.object_in_base(q)
        if xis is None:
            assert rng is not None
            xis = np.array([np.r_[rng.uniform(-o.loop_m, o.loop_m, 3), rng.uniform(-o.loop_rad, o.loop_rad, 3)]
                            for _ in range(2)])
        vias = [M * pin.exp6(pin.Motion(scale * xi)) for xi in xis]
        qs = [q]
        for A, B in zip([M] + vias, vias + [M]):
            dp = float(np.linalg.norm(B.translation - A.translation))
            dr = float(np.linalg.norm(pin.log3(A.rotation.T @ B.rotation)))
            n = max(1, math.ceil(max(dp / co.task_step_m, dr / co.task_step_rad)))
            for R, p in interpolate_task(A.rotation, A.translation, B.rotation, B.translation, n):
                qn = self.carry.hold(qs[-1], pin.SE3(R, p))
                if qn is None or float(np.max(np.abs(qn - qs[-1]))) > o.max_joint_step:
                    return None
                qs.append(qn)
        # back to the loop's start joints exactly: a self-motion join with the object held at M
        qe = qs[-1]
        n = max(1, math.ceil(float(np.max(np.abs(q - qe))) / o.join_step_rad))
        for i in range(1, n):
            qn = self.carry.hold(qe + (i / n) * (q - qe), M)
            if qn is None or float(np.max(np.abs(qn - qs[-1]))) > o.max_joint_step:
                return None
            qs.append(qn)
        if float(np.max(np.abs(q - qs[-1]))) > o.max_joint_step:
            return None
        qs.append(np.array(q, float))
        X, rows = path_displacement(self.robot, qs, co.check_step_rad)
        return _Loop(qs, X, rows, xis, scale)

    def steer(self, q: np.ndarray, base: pin.SE3, wanted: np.ndarray, rng: np.random.Generator,
              deadline: Deadline, tol_rad: float | None = None, pool: list[_Loop] | None = None) -> SteerResult | None:
        """Loops from the joints ``q`` [rad] (holding the object; base at ``base``) whose product
        turns the base by the rotation ``wanted`` (3×3, base frame: the end attitude is
        ``R_base · wanted``) to within ``tol_rad`` (default ``options.tol_rad``) [rad]: greedy
        whole loops, then (:meth:`_refine`) loops scaled to the small rotation left. None when no
        collision-free loop brings the rotation nearer. ``pool``: loops from these very joints ``q``
        found by an earlier call (used first; the new ones are added to it, the colliding ones
        removed: a caller steering from ``q`` again reuses them instead of drawing new ones)."""
        o = self.options
        tol = o.tol_rad if tol_rad is None else float(tol_rad)
        st = _State(base, wanted)
        pool = [] if pool is None else pool
        for _ in range(o.max_rounds):
            if st.err <= tol or deadline.expired():
                break
            for _ in range(o.new_loops):
                lp = self._loop(q, rng)
                if lp is not None:
                    pool.append(lp)
            E = st.P.T @ wanted   # the rotation still wanted
            options = []
            for i, lp in enumerate(pool):
                for sign in (1, -1):
                    L = lp.D.rotation if sign > 0 else lp.D.rotation.T
                    Lk = np.eye(3)
                    for k in range(1, o.max_repeat + 1):
                        Lk = Lk @ L
                        options.append((float(np.linalg.norm(pin.log3(Lk.T @ E))), i, sign, k))
            options.sort()
            bad: set[int] = set()
            for e, i, sign, k in options:
                if e >= st.err:
                    break
                if i in bad:
                    continue
                if self._append(st, pool[i], sign, k):
                    break
                bad.add(i)
            pool[:] = [lp for i, lp in enumerate(pool) if i not in bad]
        if st.err > tol and len(pool) >= 3:
            self._refine(st, q, pool, tol, deadline)
        if not st.joints:
            return None
        return SteerResult(st.joints, st.bases, base.rotation.T @ st.bases[-1].rotation, st.err, st.loops,
                           np.vstack(st.rows), base)

    def _append(self, st: _State, lp: _Loop, sign: int, k: int) -> bool:
        """``k`` traversals of ``lp`` (backwards for ``sign`` −1) appended to the manoeuvre when every
        one is collision-free with the base where momentum puts it."""
        path = lp.joints if sign > 0 else lp.joints[::-1]
        D = lp.D if sign > 0 else lp.D.inverse()
        rows0 = lp.rows if sign > 0 else _reversed_rows(lp)
        X = lp.X if sign > 0 else [D * x for x in [pin.SE3.Identity()] + lp.X[:-1]][::-1]
        Bk, new_b = st.B, []
        for _ in range(k):
            if self._checker().first_invalid(left_multiply(rows0, Bk)) >= 0:
                return False
            new_b.append(Bk)
            Bk = Bk * D
        for Bs in new_b:   # the waypoints' bases of every repetition
            st.joints += [np.array(j) for j in path[1:]]
            st.bases += [Bs * x for x in X]
            st.rows.append(left_multiply(rows0, st.base_inv * Bs))
        st.B = st.bases[-1]
        st.P = st.base.rotation.T @ st.B.rotation
        st.err = float(np.linalg.norm(pin.log3(st.P.T @ st.wanted)))
        st.loops += k
        return True

    def steer_small(self, q: np.ndarray, base: pin.SE3, wanted: np.ndarray, rng: np.random.Generator,
                    deadline: Deadline, tol_rad: float | None = None,
                    pool: list[_Loop] | None = None) -> SteerResult | None:
        """Like :meth:`steer` for a rotation ``wanted`` well below one whole loop's (a re-steering's
        1e-6-1e-3 rad), solved for instead of searched: no search for whole loops (they overshoot).

        A small loop's holonomy is, to leading order, bilinear and antisymmetric in its two via
        offsets: ``b(ξ₁, ξ₂) ≈ s²·Ω(ξ₁, ξ₂)`` (the connection's curvature on the loop's area
        bivector ``½ ξ₁ ∧ ξ₂``). Three probe loops sharing ``ξ₁`` (size ``options.probe_scale``)
        with independent holonomies ``bᵢ`` are measured (integrated, never kept); the rotation left
        ``r = Σ cᵢ bᵢ`` is then made by ONE loop with the second offset ``Σ cᵢ ξ₂ᵢ`` (the two offsets
        rescaled to a common size, their product kept; repeated ``k`` times when it would exceed
        a whole loop), and again on the rotation still left while it shrinks (the neglected terms
        are of higher order in the size). When that loop fails its IK or collides, three probes are
        scaled instead (:meth:`_refine`). ``pool``: loops from these very joints ``q`` (reused: the
        probes drawn are added). None when no three independent probes are found within
        ``options.max_probes`` draws or no loop brings the rotation nearer."""
        o = self.options
        tol = o.tol_rad if tol_rad is None else float(tol_rad)
        st = _State(base, wanted)
        pool = [] if pool is None else pool
        fam = self._family(q, rng, pool, deadline)
        if fam is not None and st.err > tol:
            xi1, X2, Bm = fam
            lim = float(np.linalg.norm([o.loop_m] * 3 + [o.loop_rad] * 3))   # a whole loop's largest offset
            for _ in range(o.refine_rounds):
                if st.err <= tol or deadline.expired():
                    break
                r = np.asarray(pin.log3(st.P.T @ st.wanted))
                xi2 = X2 @ np.linalg.solve(Bm, r)
                n1, n2 = float(np.linalg.norm(xi1)), float(np.linalg.norm(xi2))
                if n2 < 1e-15:
                    break
                g = math.sqrt(n1 * n2)   # both offsets of size √(n₁n₂): the same bivector
                k = max(1, math.ceil((o.probe_scale * g / lim) ** 2))   # k loops, each 1/k of r
                f = 1.0 / math.sqrt(k)
                xis = np.array([xi1 * (g / n1) * f, xi2 * (g / n2) * f])
                sl = self._loop(q, None, xis, o.probe_scale)
                # kept only when it brings the rotation nearer (and is collision-free)
                if sl is None or _angle(st.P @ np.linalg.matrix_power(sl.D.rotation, k), st.wanted) >= st.err \
                        or not self._append(st, sl, 1, k):
                    break
        if st.err > tol:
            mark = st.mark()
            self._refine(st, q, pool, tol, deadline)
            if st.err >= mark[-1]:
                st.restore(mark)   # the scaled trio did not help: not kept
        if not st.joints:
            return None
        return SteerResult(st.joints, st.bases, base.rotation.T @ st.bases[-1].rotation, st.err, st.loops,
                           np.vstack(st.rows), base)

    def _family(self, q: np.ndarray, rng: np.random.Generator, pool: list[_Loop],
                deadline: Deadline) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Three probe loops from ``q`` sharing the first via offset ``ξ₁`` whose holonomies are
        independent (:meth:`_trio`): ``(ξ₁, [ξ₂ᵢ] as the columns of a 6 × 3 matrix, [bᵢ] as the
        columns of a 3 × 3 one)``, the probes' own size ``options.probe_scale``; those in ``pool``
        are reused, the new ones added to it. A first offset whose first four probes all fail is
        replaced. None after ``options.max_probes`` draws."""
        o = self.options

        def fam_of(xi1: np.ndarray) -> list[_Loop]:
            return [lp for lp in pool if lp.scale == o.probe_scale and np.array_equal(lp.xis[0], xi1)]

        firsts = [lp.xis[0] for lp in pool if lp.scale == o.probe_scale]
        xi1 = firsts[0] if firsts else None
        tried = 0
        best = None
        for _ in range(o.max_probes + 1):
            if xi1 is not None:
                got = _best_trio(fam_of(xi1))
                if got is not None and (best is None or got[0] > best[0]):
                    best = (got[0], xi1, got[1], got[2])
                if best is not None and best[0] >= 0.3:
                    break
            if deadline.expired():
                break
            if xi1 is None or (tried >= 4 and not fam_of(xi1)):
                xi1, tried = np.r_[rng.uniform(-o.loop_m, o.loop_m, 3), rng.uniform(-o.loop_rad, o.loop_rad, 3)], 0
            xi2 = np.r_[rng.uniform(-o.loop_m, o.loop_m, 3), rng.uniform(-o.loop_rad, o.loop_rad, 3)]
            tried += 1
            lp = self._loop(q, None, np.array([xi1, xi2]), o.probe_scale)
            if lp is not None:
                pool.append(lp)
        if best is None or best[0] < 0.05:
            return None
        _, xi1, trio, Bm = best
        return xi1, np.array([lp.xis[1] for lp in trio]).T, Bm

    @staticmethod
    def _trio(pool: list[_Loop]) -> tuple[list[_Loop], np.ndarray] | None:
        """Three loops of ``pool`` whose holonomies (rotation vectors ``b``, the columns of the 3 × 3
        matrix returned) are independent enough to compose any small rotation (the normalised
        determinant ≥ 0.05): the largest, the one most across it, the one most out of their plane.
        None when the pool has no such three."""
        if len(pool) < 3:
            return None
        b = np.array([pin.log3(lp.D.rotation) for lp in pool])
        nrm = np.linalg.norm(b, axis=1)
        i0 = int(np.argmax(nrm))
        u = b / np.maximum(nrm, 1e-12)[:, None]
        i1 = int(np.argmax(np.linalg.norm(np.cross(u, u[i0]), axis=1) * nrm))
        i2 = int(np.argmax(np.abs(u @ np.cross(u[i0], u[i1])) * nrm))
        Bm = np.array([b[i] for i in (i0, i1, i2)]).T
        if abs(np.linalg.det(Bm / np.maximum(np.linalg.norm(Bm, axis=0), 1e-12))) < 0.05:
            return None
        return [pool[i] for i in (i0, i1, i2)], Bm

    def _refine(self, st: _State, q: np.ndarray, pool: list[_Loop], tol: float, deadline: Deadline) -> None:
        """The small rotation left, ``r``, by three loops of the pool scaled: a loop's holonomy
        grows with the square of its size (``s²·b`` to leading order), so ``r = Σ cᵢ bᵢ`` gives
        each loop's scale ``√|cᵢ|`` times its own (at most the whole loop, scale 1) and direction
        (the sign of ``cᵢ``); repeated while it converges (the neglected terms are of higher order
        in the scale)."""
        got = self._trio(pool)
        if got is None:
            return
        trio, Bm = got
        for _ in range(self.options.refine_rounds):
            if st.err <= tol or deadline.expired():
                return
            r = np.asarray(pin.log3(st.P.T @ st.wanted))
            c = np.linalg.solve(Bm, r)
            err0 = st.err
            for ci, lp in zip(c, trio):
                s = min(lp.scale * math.sqrt(abs(float(ci))), 1.0)
                if s < 1e-6:
                    continue
                sl = self._loop(q, None, lp.xis, s)
                if sl is None or not self._append(st, sl, 1 if ci > 0 else -1, 1):
                    return
            if st.err >= err0:
                return


def _best_trio(loops: list[_Loop]) -> tuple[float, list[_Loop], np.ndarray] | None:
    """The three of ``loops`` whose holonomies (rotation vectors) are the most independent: (the
    normalised determinant |det [b̂₁ b̂₂ b̂₃]| [1], the loops, the 3 × 3 matrix of their ``b`` as
    columns); None with fewer than three loops."""
    if len(loops) < 3:
        return None
    b = np.array([pin.log3(lp.D.rotation) for lp in loops])
    u = b / np.maximum(np.linalg.norm(b, axis=1), 1e-300)[:, None]
    d, ijk = max((abs(float(np.linalg.det(u[list(c)]))), c) for c in itertools.combinations(range(len(loops)), 3))
    return d, [loops[i] for i in ijk], b[list(ijk)].T


def _angle(P: np.ndarray, wanted: np.ndarray) -> float:
    """The angle between the rotations ``P`` and ``wanted`` [rad]."""
    return float(np.linalg.norm(pin.log3(P.T @ wanted)))


@dataclass
class _State:
    """The manoeuvre being built: waypoints, bases, samples (relative to ``base``), the current base
    ``B``, the rotation made ``P`` (base frame) and the angle ``err`` left to ``wanted``."""

    base: pin.SE3
    wanted: np.ndarray

    def __post_init__(self) -> None:
        self.base_inv = self.base.inverse()
        self.joints: list[np.ndarray] = []
        self.bases: list[pin.SE3] = []
        self.rows: list[np.ndarray] = []
        self.B = self.base
        self.P = np.eye(3)
        self.err = float(np.linalg.norm(pin.log3(self.wanted)))
        self.loops = 0

    def mark(self) -> tuple[Any, ...]:
        """What :meth:`restore` needs to undo the loops appended after this call (``err`` last)."""
        return len(self.joints), len(self.bases), len(self.rows), self.B, self.P, self.loops, self.err

    def restore(self, mark: tuple[Any, ...]) -> None:
        """The manoeuvre as it was at :meth:`mark`."""
        nj, nb, nr, self.B, self.P, self.loops, self.err = mark
        del self.joints[nj:], self.bases[nb:], self.rows[nr:]


def _reversed_rows(lp: _Loop) -> np.ndarray:
    """The samples of the loop traversed backwards, from the identity base: the point that the
    forward traversal reaches with displacement ``X`` is reached backwards with ``D⁻¹ X``."""
    full = np.vstack([np.r_[pin.SE3ToXYZQUAT(pin.SE3.Identity()), lp.joints[0]], lp.rows])
    Dinv = lp.D.inverse()
    out = left_multiply(full[::-1], Dinv)
    return out[1:]

