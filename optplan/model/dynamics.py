"""CasADi inverse dynamics (recursive Newton-Euler) of a :class:`RobotModel`, built from the same
Pinocchio model and joint description as :class:`~optplan.model.symbolic.SymbolicKinematics`
(free-flyer root, 1-DoF revolute/prismatic joints about any axis, mimic joints). The PyPI ``pin``
wheel has no ``pinocchio.casadi``, so the recursion is written here over SX.

Spatial quantities are in world axes at the world origin, ``(ω, v_O)`` for motions and
``(F, n_O)`` for forces (force first, as Pinocchio's ``Force``). Gravity is the model's
(``model.gravity``), applied as an acceleration ``−g`` of the world, as Pinocchio does.

* Fixed base: :meth:`SymbolicDynamics.rnea` is ``pinocchio.rnea`` (generalized forces
  ``τ = M(q) q̈ + C(q, q̇) q̇ + g(q)`` [N·m or N]); :meth:`SymbolicDynamics.base_reaction_wrench`
  the wrench the robot exerts on its mount.
* Free-floating base, no external wrench: the base is unactuated and the momentum is zero (as in
  :mod:`optplan.model.floating` and the transcription). Given the joints ``(q, q̇, q̈)`` the base
  twist follows from zero momentum and the base acceleration from the base rows of
  ``M a + h = 0``; the joint torques are then the joint rows. Both solves use the closed-form
  inverse of the whole robot's spatial inertia (its mass, CoM and rotational inertia about the
  CoM), so the expressions contain no symbolic matrix factorisation. In free fall the internal
  forces do not depend on the base pose or on a uniform gravity field, so the base is placed at
  the identity.
"""
from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ..errors import ModelError
from .robot import RobotModel
from .symbolic import SymbolicKinematics

__all__ = ["SymbolicDynamics"]

Expr = Any


def _motion_cross(V: tuple[Expr, Expr], S: tuple[Expr, Expr]) -> tuple[Expr, Expr]:
    """Spatial motion cross product ``V ×m S`` with motions stored ``(ω, v_O)``."""
    w, v = V
    ws, vs = S
    return ca.cross(w, ws), ca.cross(w, vs) + ca.cross(v, ws)


class SymbolicDynamics:
    """Symbolic inverse dynamics of a robot (fixed or free-floating base).

    ``tau`` (a ``casadi.Function`` ``(q, v, a) -> tau``) gives the joint torques [N·m or N] of the
    actuated joints (``nj`` each): for a fixed base, ``pinocchio.rnea``; for a free-floating base,
    the torques that produce the joint accelerations ``a`` with zero base wrench and zero momentum.
    ``rnea`` (full Pinocchio ``q``, ``v``, ``a``) is the generalized force of every velocity
    coordinate, base rows included; ``base_reaction_wrench`` (fixed base) ``(q, v, a) -> w`` the
    wrench ``[F [N]; n [N·m]]`` the robot exerts on its mount, world axes, at the world origin.
    """

    def __init__(self, robot: RobotModel, kinematics: SymbolicKinematics | None = None):
        self.robot = robot
        self.model = robot.model
        self.kin = kinematics if kinematics is not None and kinematics.robot is robot else SymbolicKinematics(robot)
        self.joints = self.kin.joints
        self.floating = robot.is_floating
        if self.floating and (self.joints[1] is None or self.joints[1].kind != "free_flyer"):
            raise ModelError(f"{robot.name!r}: a floating robot's first joint must be the free-flyer")
        g = np.asarray(self.model.gravity.linear, float)
        self._gravity = g
        # body inertias: (joint, mass, lever in joint frame, rotational inertia about the CoM)
        self._bodies = [(j, float(I.mass), np.array(I.lever, float), np.array(I.inertia, float))
                        for j, I in enumerate(self.model.inertias) if j > 0 and I.mass > 0]
        self._functions: dict[str, ca.Function] = {}

    # ------------------------------------------------------------------ core recursion
    def _pass(self, q: Expr, v: Expr, a: Expr, X: list | None = None
              ) -> tuple[list[tuple[Expr, Expr]], list[tuple[Expr, Expr]], list[Expr]]:
        """Forward (velocities, accelerations, body wrenches) and backward (joint forces) passes.
        Returns ``(X, f_joint, tau)``: placements, the wrench transmitted through each joint from
        its parent to its subtree ``(F, n_O)``, and the generalized forces (nv)."""
        model, J = self.model, self.joints
        X = self.kin.joint_placements(q) if X is None else X
        nj = model.njoints
        zero = ca.DM.zeros(3)
        Vel: list[tuple[Expr, Expr]] = [(zero, zero)]
        Acc: list[tuple[Expr, Expr]] = [(zero, ca.DM(-self._gravity))]
        cols: list[list[tuple[int, Expr, Expr]]] = [[]]
        for j in range(1, nj):
            jt = J[j]
            assert jt is not None   # joint 0 is the universe
            c = self.kin._columns(j, X)
            cols.append(c)
            w, vO = Vel[jt.parent]
            dw, dv = Acc[jt.parent]
            for idx, wc, vc in c:
                w, vO = w + wc * v[idx], vO + vc * v[idx]
            for idx, wc, vc in c:   # d/dt of a column fixed in the moving body: V ×m S
                sw, sv = _motion_cross((w, vO), (wc, vc))
                dw = dw + wc * a[idx] + sw * v[idx]
                dv = dv + vc * a[idx] + sv * v[idx]
            Vel.append((w, vO))
            Acc.append((dw, dv))
        F: list[Expr] = [zero] * nj
        n: list[Expr] = [zero] * nj
        for b, m, lever, Ic in self._bodies:
            R, p = X[b]
            c_w = p + R @ ca.DM(lever)
            w, vO = Vel[b]
            dw, dv = Acc[b]
            vc = vO + ca.cross(w, c_w)
            ac = dv + ca.cross(dw, c_w) + ca.cross(w, vc)
            Iw = R @ ca.DM(Ic) @ R.T
            Fb = m * ac
            F[b] = Fb
            n[b] = ca.cross(c_w, Fb) + Iw @ dw + ca.cross(w, Iw @ w)
        tau: list[Expr] = [0] * model.nv
        for j in range(nj - 1, 0, -1):
            jt = J[j]
            assert jt is not None
            for idx, wc, vc in cols[j]:
                tau[idx] = tau[idx] + ca.dot(vc, F[j]) + ca.dot(wc, n[j])
            if jt.parent > 0:
                F[jt.parent] = F[jt.parent] + F[j]
                n[jt.parent] = n[jt.parent] + n[j]
            else:
                F[0] = F[0] + F[j]
                n[0] = n[0] + n[j]
        return X, list(zip(F, n)), tau

    def rnea(self, q: Expr, v: Expr, a: Expr) -> Expr:
        """Generalized forces (nv) for the full Pinocchio ``q`` (nq), ``v``, ``a`` (nv) —
        ``pinocchio.rnea(model, data, q, v, a)`` (a free-flyer's rows: the wrench on the base in
        its own frame, ``[F; n]``)."""
        _, _, tau = self._pass(q, v, a)
        return ca.vertcat(*tau)

    def base_reaction_wrench(self, q: Expr, v: Expr, a: Expr) -> Expr:
        """``[F [N]; n [N·m]]``: the wrench the robot exerts on its fixed mount (world axes, moment
        about the world origin) — minus the wrench the mount applies through the root joints,
        ``−(ḣ − m g)`` with ``h`` the robot's spatial momentum."""
        if self.floating:
            raise ModelError(f"base_reaction_wrench: {self.robot.name!r} has a free-floating base (no mount; its "
                             "base wrench is zero by construction)")
        _, f, _ = self._pass(q, v, a)
        F0, n0 = f[0]
        return ca.vertcat(-F0, -n0)

    # ------------------------------------------------------------------ free-floating base
    def _inverse_total_inertia(self, X: list) -> Any:
        """``f -> A``: the spatial acceleration (world, at the origin) of the robot frozen as one
        rigid body under the wrench ``f = (F, n_O)``, in closed form from its mass ``m``, CoM
        ``c`` and rotational inertia about the CoM ``I_c``: ``ω̇ = I_c⁻¹ (n_O − c × F)``,
        ``a_O = F/m − ω̇ × c``."""
        mtot = sum(m for _, m, _, _ in self._bodies)
        cs = []
        for b, m, lever, Ic in self._bodies:
            R, p = X[b]
            cs.append((m, p + R @ ca.DM(lever), R @ ca.DM(Ic) @ R.T))
        c = sum((m * cb for m, cb, _ in cs[1:]), cs[0][0] * cs[0][1]) / mtot
        Itot = 0
        for m, cb, Iw in cs:
            d = cb - c
            Itot = Itot + Iw + m * (ca.dot(d, d) * ca.DM.eye(3) - d @ d.T)
        Iinv = ca.inv(Itot)   # 3 × 3, closed form (adjugate / determinant)

        def solve(F: Expr, n: Expr) -> tuple[Expr, Expr]:
            dw = Iinv @ (n - ca.cross(c, F))
            return dw, F / mtot - ca.cross(dw, c)
        return solve

    def floating_state(self, qj: Expr, vj: Expr, aj: Expr) -> tuple[Expr, Expr, Expr]:
        """Full ``(q, v, a)`` of a free-floating robot with the base at the identity, the base
        twist from zero momentum and the base acceleration that makes the base wrench zero, for
        the joint values ``qj`` [rad], rates ``vj`` [rad/s] and accelerations ``aj`` [rad/s²]."""
        if not self.floating:
            raise ModelError(f"floating_state: {self.robot.name!r} has a fixed base")
        q = ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), qj)
        X = self.kin.joint_placements(q)
        solve = self._inverse_total_inertia(X)
        # momentum of the joint motion alone (base at rest), then the base twist cancelling it
        h = self.kin.momentum(q, ca.vertcat(ca.DM.zeros(6), vj), X)
        wb, vb = solve(-h[:3], -h[3:])           # spatial twist at the origin = the base's (base at origin)
        v = ca.vertcat(vb, wb, vj)               # Pinocchio free-flyer: [linear; angular] in the base frame
        _, f, _ = self._pass(q, v, ca.vertcat(ca.DM.zeros(6), aj), X)
        dwb, dvb = solve(-f[0][0], -f[0][1])      # base wrench of that motion, cancelled
        return q, v, ca.vertcat(dvb, dwb, aj)     # V_b × V_b = 0: the spatial and local accelerations agree

    def joint_torques(self, qj: Expr, vj: Expr, aj: Expr) -> Expr:
        """Joint torques (nj) [N·m or N] for joint values, rates and accelerations (fixed base:
        :meth:`rnea`; free-floating: with zero base wrench and zero momentum)."""
        if not self.floating:
            return self.rnea(qj, vj, aj)
        q, v, a = self.floating_state(qj, vj, aj)
        _, _, tau = self._pass(q, v, a)
        return ca.vertcat(*tau[6:])

    # ------------------------------------------------------------------ casadi.Function wrappers
    def _cached(self, key: str, build: Any) -> ca.Function:
        if key not in self._functions:
            self._functions[key] = build()
        return self._functions[key]

    @property
    def tau(self) -> ca.Function:
        """``tau(q, v, a) -> tau`` (nj each): :meth:`joint_torques` as an SX ``casadi.Function``."""
        def build() -> ca.Function:
            nj = self.robot.nj
            q, v, a = (ca.SX.sym(s, nj) for s in ("q", "v", "a"))
            return ca.Function("tau", [q, v, a], [self.joint_torques(q, v, a)], ["q", "v", "a"], ["tau"])
        return self._cached("tau", build)

    @property
    def rnea_function(self) -> ca.Function:
        """``rnea(q, v, a) -> tau`` for the full Pinocchio state (nq, nv, nv)."""
        def build() -> ca.Function:
            q = ca.SX.sym("q", self.model.nq)
            v, a = ca.SX.sym("v", self.model.nv), ca.SX.sym("a", self.model.nv)
            return ca.Function("rnea", [q, v, a], [self.rnea(q, v, a)], ["q", "v", "a"], ["tau"])
        return self._cached("rnea", build)

    @property
    def base_reaction_wrench_function(self) -> ca.Function:
        """``w(q, v, a) -> wrench`` (6) of a fixed-base robot: :meth:`base_reaction_wrench`."""
        def build() -> ca.Function:
            nj = self.robot.nj
            q, v, a = (ca.SX.sym(s, nj) for s in ("q", "v", "a"))
            return ca.Function("base_reaction_wrench", [q, v, a], [self.base_reaction_wrench(q, v, a)],
                               ["q", "v", "a"], ["wrench"])
        return self._cached("wrench", build)

    @property
    def floating_state_function(self) -> ca.Function:
        """``(qj, vj, aj) -> (q, v, a)``: :meth:`floating_state` as a ``casadi.Function``."""
        def build() -> ca.Function:
            nj = self.robot.nj
            q, v, a = (ca.SX.sym(s, nj) for s in ("qj", "vj", "aj"))
            return ca.Function("floating_state", [q, v, a], list(self.floating_state(q, v, a)),
                               ["qj", "vj", "aj"], ["q", "v", "a"])
        return self._cached("floating_state", build)
