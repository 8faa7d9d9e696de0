"""Figures of a planned trajectory (``optplan plan --plot DIR``): joint trajectories against their
limits, closed-chain residual and clearance over time, computed independently of the optimizer
(Pinocchio forward kinematics and exact coal distances at the trajectory's samples)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import save_figure

__all__ = ["trajectory_profiles", "plot_trajectory"]


def _subsample(n: int, max_samples: int) -> np.ndarray:
    if n <= max_samples:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_samples).round().astype(int))


def trajectory_profiles(robot, scene, t, q, constrained=None, max_samples: int = 400) -> dict:
    """Residual and clearance at up to ``max_samples`` samples of the trajectory.

    Returns ``t`` [s], ``residual_m`` and ``residual_rad`` (closed-chain error of the hands'
    relative pose, NaN where the chain is open), ``clearance_m`` (exact smallest distance over
    self, robot-obstacle and — while the chain holds — object pairs; while it is open the object
    stays where it is and only the robot is checked) and ``constrained``."""
    from ..collision.checker import CollisionChecker
    from ..constraints.closed_chain import closure_error

    t = np.asarray(t, float)
    q = np.asarray(q, float)
    cons = (np.ones(len(q), bool) if constrained is None or len(constrained) != len(q)
            else np.asarray(constrained, bool))
    idx = _subsample(len(q), max_samples)
    has_obj = scene is not None and scene.object is not None and len(scene.object.grasps) == 2
    held = CollisionChecker(robot, scene, held_object=True) if has_obj else None
    free = CollisionChecker(robot, scene, held_object=False)
    data = robot.model.createData()
    rp = np.full(len(idx), np.nan)
    rr = np.full(len(idx), np.nan)
    cl = np.empty(len(idx))
    for j, k in enumerate(idx):
        if held is not None and scene is not None and scene.object is not None and cons[k]:
            rp[j], rr[j] = closure_error(robot, scene.object.grasps, q[k], data)
            cl[j] = held.min_distance(q[k])[0]
        else:
            cl[j] = free.min_distance(q[k])[0]
    return {"t": t[idx], "residual_m": rp, "residual_rad": rr, "clearance_m": cl, "constrained": cons[idx]}


#: legend entry of the grey bands
REGRASP_LABEL = "regrasp (closed chain open)"


def _shade_open(ax, t, cons) -> bool:
    """Grey bands where the closed chain is open (regrasps); the first one carries the legend
    label :data:`REGRASP_LABEL`. Returns whether any band was drawn."""
    k = 0
    n = len(t)
    drawn = False
    while k < n:
        if cons[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and not cons[j + 1]:
            j += 1
        ax.axvspan(t[k], t[j], color="0.85", zorder=0, lw=0, label=None if drawn else REGRASP_LABEL)
        drawn = True
        k = j + 1
    return drawn


def plot_trajectory(robot, scene, t, q, out_dir, name: str = "plan", constrained=None,
                    max_samples: int = 400) -> list[Path]:
    """Write ``<name>_joints.png`` (every joint [deg] with its limits, one panel per joint,
    arms in columns) and ``<name>_residual_clearance.png`` (closed-chain residual and clearance
    over time, regrasps shaded) to ``out_dir``; returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .html import ARM_COLORS

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    cons = (np.ones(len(q), bool) if constrained is None or len(constrained) != len(q)
            else np.asarray(constrained, bool))
    paths = []

    # joints, one column per arm
    arms = list(robot.arms.values())
    cols = max(1, len(arms))
    rows = max((a.n for a in arms), default=robot.nj)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 1.35 * rows + 0.8), sharex=True, squeeze=False)
    for c, arm in enumerate(arms):
        for r in range(rows):
            ax = axes[r, c]
            if r >= arm.n:
                ax.set_visible(False)
                continue
            qi = int(arm.q_idx[r])
            ji = int(arm.j_idx[r])
            ax.plot(t, np.degrees(q[:, qi]), lw=1.2, color=ARM_COLORS[c % len(ARM_COLORS)][:3])
            lo, hi = np.degrees(robot.lower[ji]), np.degrees(robot.upper[ji])
            for lim in (lo, hi):
                if np.isfinite(lim):
                    ax.axhline(lim, ls="--", lw=0.9, color="crimson")
            _shade_open(ax, t, cons)
            ax.set_ylabel(f"{arm.joint_names[r]}\n[deg]", fontsize=7)
            ax.tick_params(labelsize=7)
            if r == 0:
                ax.set_title(f"arm {arm.name} (dashed: joint limits; grey: regrasp)", fontsize=8)
        axes[-1, c].set_xlabel("t [s]")
    paths.append(save_figure(fig, out / f"{name}_joints.png"))

    prof = trajectory_profiles(robot, scene, t, q, cons, max_samples)
    fig, ax = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    tt = prof["t"]
    if np.any(np.isfinite(prof["residual_m"])):
        ax[0].semilogy(tt, np.maximum(prof["residual_m"], 1e-16), label="position [m]")
        ax[0].semilogy(tt, np.maximum(prof["residual_rad"], 1e-16), label="orientation [rad]")
        ax[0].axhline(1e-6, ls="--", color="crimson", lw=0.9, label="tolerance 1e-6")
    else:
        ax[0].text(0.5, 0.5, "no closed chain in this trajectory", ha="center", va="center", transform=ax[0].transAxes)
    ax[0].set_ylabel("closed-chain residual")
    _shade_open(ax[0], tt, prof["constrained"])
    ax[1].plot(tt, prof["clearance_m"], color="C2", label="clearance")
    ax[1].axhline(0.0, ls="--", color="crimson", lw=0.9, label="contact (0 m)")
    ax[1].set_ylabel("clearance [m] (coal)")
    ax[1].set_xlabel("t [s]")
    _shade_open(ax[1], tt, prof["constrained"])
    for a in ax:   # after the bands, so that the grey regrasp band has its entry
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=8)
    ax[0].set_title(f"{robot.name}" + (f" in {scene.name}" if scene is not None else "")
                    + f": min clearance {np.nanmin(prof['clearance_m']):+.3f} m", fontsize=9)
    paths.append(save_figure(fig, out / f"{name}_residual_clearance.png"))
    return paths
