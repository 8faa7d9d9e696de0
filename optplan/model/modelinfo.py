"""``optplan models info NAME|PATH``: what a robot model is, read off its Pinocchio model
(joints and limits, arms and end-effector frames, reach, masses, collision geometry, the fitted
capsules and the self-collision pair budget)."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["model_info", "format_model_info"]


def _deg(x: float) -> float | None:
    return None if not math.isfinite(x) else float(np.degrees(x))


def model_info(name: str) -> dict:
    """A JSON-friendly description of the robot ``name`` (a shipped model, a robot file or a URDF
    path; angles [deg], rates [deg/s], masses [kg], lengths [m], volumes [m³])."""
    from .example_robots import load_robot

    robot = load_robot(name)
    m = robot.model
    joints = []
    for k, jn in enumerate(robot.joint_names):
        jid = int(m.getJointId(jn))
        arm = next((a.name for a in robot.arms.values() if jn in a.joint_names), None)
        joints.append({"name": jn, "arm": arm, "lower_deg": _deg(robot.lower[k]), "upper_deg": _deg(robot.upper[k]),
                       "velocity_limit_deg_s": _deg(robot.velocity_limit[k]),
                       "body_mass_kg": float(m.inertias[jid].mass)})
    total = float(sum(m.inertias[j].mass for j in range(m.njoints)))   # joint 0: a fixed base's own body
    base_mass = float(m.inertias[1].mass) if robot.is_floating else float(m.inertias[0].mass)
    arms = {}
    for a in robot.arms.values():
        arms[a.name] = {"joints": list(a.joint_names), "ee_frame": a.ee_frame,
                        "mass_kg": float(sum(m.inertias[int(m.getJointId(j))].mass for j in a.joint_names))}
    geoms = robot.collision_model.geometryObjects
    kinds: dict = {}
    for g in geoms:
        kinds[type(g.geometry).__name__] = kinds.get(type(g.geometry).__name__, 0) + 1
    if not robot.is_floating:
        from .reach import arm_reach_estimate

        for arm_name in robot.arms:
            est, bound = arm_reach_estimate(robot, arm_name)
            arms[arm_name]["reach_m"], arms[arm_name]["reach_bound_m"] = est, bound
    judge = robot.judge
    jk: dict = {}
    for g in judge.collision_model.geometryObjects:
        jk[type(g.geometry).__name__] = jk.get(type(g.geometry).__name__, 0) + 1
    return {"name": robot.name, "base": "floating" if robot.is_floating else "fixed", "nq": robot.nq, "nv": robot.nv,
            "n_joints": robot.nj, "total_mass_kg": total, "base_mass_kg": base_mass, "arms": arms, "joints": joints,
            "collision_geometry": kinds, "self_collision_pairs": len(robot.collision_pairs),
            "verification_geometry": None if judge is robot else jk,
            "pair_budget": getattr(robot, "pair_budget", None),
            "fitted_primitives": getattr(robot, "primitive_report", None) or None,
            "urdf": None if robot.urdf_path is None else str(robot.urdf_path)}


def format_model_info(d: dict) -> str:
    lines = [f"{d['name']}: {d['base']} base, {d['n_joints']} joints (nq = {d['nq']}, nv = {d['nv']}), "
             f"total mass {d['total_mass_kg']:.2f} kg (base {d['base_mass_kg']:.2f} kg)",
             f"  URDF {d['urdf']}",
             "  collision geometry: " + ", ".join(f"{v} {k}" for k, v in d["collision_geometry"].items())
             + f"; {d['self_collision_pairs']} self-collision pairs checked"]
    if d.get("verification_geometry"):
        lines.append("  verification geometry (exact): " + ", ".join(f"{v} {k}" for k, v in d["verification_geometry"].items()))
    b = d.get("pair_budget")
    if b:
        lines.append("  pair budget: " + ", ".join(f"{k} {v}" for k, v in b.items() if not isinstance(v, list)))
    fits = d.get("fitted_primitives")
    if fits:
        lines.append(f"  {'mesh':28s} {'capsules':>8s} {'vertices':>8s} {'volume ratio':>12s} {'radius [m]':>12s}")
        for g, f_ in fits.items():
            lines.append(f"  {g:28s} {f_['capsules']:8d} {f_['vertices']:8d} {f_['ratio']:12.2f} "
                         f"{', '.join(f'{r:.4f}' for r in f_['radius_m']):>12s}")
    for a, info in d["arms"].items():
        reach = "" if "reach_m" not in info else \
            f", reach {info['reach_m']:.3f} m (sampled; bound {info['reach_bound_m']:.3f} m)"
        lines.append(f"  arm {a}: {len(info['joints'])} joints, end effector {info['ee_frame']!r}, "
                     f"links {info['mass_kg']:.2f} kg{reach}")
    lines.append(f"  {'joint':16s} {'arm':>4s} {'lower [deg]':>12s} {'upper [deg]':>12s} {'rate [deg/s]':>13s} "
                 f"{'mass [kg]':>10s}")

    def f(v):
        return "inf" if v is None else f"{v:.1f}"
    for j in d["joints"]:
        lines.append(f"  {j['name']:16s} {j['arm'] or '-':>4s} {f(j['lower_deg']):>12s} {f(j['upper_deg']):>12s} "
                     f"{f(j['velocity_limit_deg_s']):>13s} {j['body_mass_kg']:10.2f}")
    return "\n".join(lines)
