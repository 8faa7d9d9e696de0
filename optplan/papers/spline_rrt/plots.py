"""Figures of the Spline-RRT* reproduction (matplotlib, Agg): the equivalents of the paper's Fig. 3
(tree, rewired branches, RRT* path and spline), Fig. 5 (hand paths and speeds), Fig. 6 (joint
angles, rates, accelerations), Fig. 7 (tracking errors) and Fig. 8 (link distances), with the
optimized variant overlaid where it exists."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...viz import save_figure

__all__ = ["write_figures"]


def write_figures(res, directory) -> list[Path]:
    """Write ``fig3_tree.png`` … ``fig8_link_distance.png`` for a :class:`SplineRRTResult`; returns
    the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    out = []
    arms = list(res.hands)
    ev = res.evaluation
    evo = res.optimized["executed_evaluation"] if res.optimized else None

    # Fig. 3: trees (top view and side view)
    fig = plt.figure(figsize=(12, 5))
    for k, (i, j, lab) in enumerate(((0, 1, "y"), (0, 2, "z"))):
        ax = fig.add_subplot(1, 2, k + 1)
        for a in arms:
            tr = res.plan.trees[a]
            S = np.array(tr.samples)
            ax.plot(S[:, i], S[:, j], "x", color="tab:blue", ms=2, alpha=0.3)
            for v in range(1, tr.n):
                p = tr.parent[v]
                ax.plot(tr.X[[p, v], i], tr.X[[p, v], j], "k-", lw=0.4)
            for _old, x, new in tr.rewired_edges[-200:]:
                ax.plot([new[i], x[i]], [new[j], x[j]], "-", color="tab:green", lw=0.6, alpha=0.6)
            W = res.plan.paths[a]
            ax.plot(W[:, i], W[:, j], "r-o", lw=1.5, ms=3, label=f"RRT* path {a}")
            P = res.hands[a].position(np.linspace(0, res.T, 400))
            ax.plot(P[:, i], P[:, j], "b-", lw=2, label=f"spline {a}")
        for o in res.task.scene.obstacles:
            c = o.placement.translation
            ax.add_patch(plt.Circle((c[i], c[j]), o.radius or 0.05, color="gray", alpha=0.5))
        ax.set_xlabel("x [m]")
        ax.set_ylabel(f"{lab} [m]")
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    fig.axes[0].legend(fontsize=7)
    fig.suptitle("Fig. 3 equivalent: coordinated RRT* trees (samples ×, branches, rewired in green), paths, splines")
    out.append(_save(fig, d / "fig3_tree.png"))

    # Fig. 5: hand positions and speeds
    fig, axs = plt.subplots(2, 2, figsize=(11, 7))
    t = np.linspace(0, res.T, 600)
    for c, a in enumerate(arms):
        h = res.hands[a]
        axs[0, c].plot(t, h.position(t))
        axs[0, c].set_title(f"hand {a}: position [m]")
        axs[0, c].legend(["x", "y", "z"], fontsize=7)
        v = h.position(t, 1)
        axs[1, c].plot(t, v)
        axs[1, c].plot(t, np.linalg.norm(v, axis=1), "k", lw=2)
        axs[1, c].axhline(0.1, color="r", ls="--")
        axs[1, c].set_title(f"hand {a}: velocity, ‖v‖ [m/s] (limit 0.1)")
        axs[1, c].set_xlabel("t [s]")
    out.append(_save(fig, d / "fig5_planned_path.png"))

    # Fig. 6: joints
    fig, axs = plt.subplots(3, 1, figsize=(10, 9), sharex=True)
    for k, (key, lab) in enumerate(((None, "angle [deg]"), ("qd", "rate [deg/s]"), ("qdd", "acceleration [deg/s²]"))):
        Y = ev["q"][:, 7:] if key is None else ev[key]
        axs[k].plot(ev["t"], np.degrees(Y), lw=0.8)
        if evo is not None:
            Yo = evo["q"][:, 7:] if key is None else evo[key]
            axs[k].plot(evo["t"], np.degrees(Yo), "--", lw=0.6)
        axs[k].set_ylabel(lab)
        axs[k].grid(alpha=0.3)
    axs[0].set_title("Fig. 6 equivalent: joint motion (solid: Spline-RRT*, dashed: optimized, executed)")
    axs[-1].set_xlabel("t [s]")
    out.append(_save(fig, d / "fig6_joints.png"))

    # Fig. 7: tracking errors
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    for a in arms:
        axs[0].semilogy(ev["t"], np.maximum(ev[f"tracking_position_m_{a}"], 1e-16), label=f"{a}")
        axs[1].semilogy(ev["t"], np.maximum(ev[f"tracking_orientation_rad_{a}"], 1e-16), label=f"{a}")
        if evo is not None:
            axs[0].semilogy(evo["t"], np.maximum(evo[f"tracking_position_m_{a}"], 1e-16), "--", label=f"{a} optimized")
            axs[1].semilogy(evo["t"], np.maximum(evo[f"tracking_orientation_rad_{a}"], 1e-16), "--",
                            label=f"{a} optimized")
    axs[0].set_title("position error [m]")
    axs[1].set_title("orientation error [rad]")
    for ax in axs:
        ax.legend(fontsize=7)
        ax.set_xlabel("t [s]")
        ax.grid(alpha=0.3)
    fig.suptitle("Fig. 7 equivalent: tracking errors (independent base simulator)")
    out.append(_save(fig, d / "fig7_tracking_error.png"))

    # Fig. 8: link distances and base attitude
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    axs[0].plot(ev["t"], ev["link_distance_m"], label="Spline-RRT*")
    if evo is not None:
        axs[0].plot(evo["t"], evo["link_distance_m"], "--", label="optimized")
    axs[0].axhline(0.1, color="r", ls="--", label="d_i = 0.1 m")
    axs[0].set_title("min distance, links 3/5/7 of A vs B [m]")
    axs[0].legend(fontsize=7)
    axs[1].plot(ev["t"], np.degrees(ev["base_rpy"]))
    if evo is not None:
        axs[1].plot(evo["t"], np.degrees(evo["base_rpy"]), "--")
    axs[1].set_title("base roll, pitch, yaw [deg] (dashed: optimized)")
    for ax in axs:
        ax.set_xlabel("t [s]")
        ax.grid(alpha=0.3)
    fig.suptitle("Fig. 8 equivalent: link distances; base attitude")
    out.append(_save(fig, d / "fig8_link_distance.png"))
    return out


_save = save_figure
