"""Per-trial distributions of the benchmarks' result lines (``results.jsonl``): one box (with the
individual trials on top) per planner or mode, one panel per scene. Failed trials are not
points: each box is labelled with its successes out of its trials."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import save_figure

__all__ = ["plot_time_distributions", "plot_warmstart_distributions"]


def _boxes(ax, groups: list[tuple[str, list[float], int]], ylabel: str, log: bool = True, limit: float | None = None):
    """``groups``: (label, values of the successful trials, number of trials)."""
    rng = np.random.default_rng(0)   # jitter of the points only
    data = [np.asarray(v, float) for _, v, _ in groups]
    pos = np.arange(1, len(groups) + 1)
    nonempty = [i for i, d in enumerate(data) if d.size]
    if nonempty:
        ax.boxplot([data[i] for i in nonempty], positions=pos[nonempty], widths=0.55, showfliers=False,
                   medianprops={"color": "crimson"})
    for i, d in enumerate(data):
        if d.size:
            ax.scatter(pos[i] + rng.uniform(-0.18, 0.18, d.size), d, s=8, alpha=0.5, color=f"C{i}", zorder=3)
    ax.set_xticks(pos, [f"{lab}\n{len(v)}/{n} ok" for lab, v, n in groups], fontsize=7)
    if log and any(d.size and np.all(d > 0) for d in data):
        ax.set_yscale("log")
    if limit is not None:
        ax.axhline(limit, ls="--", color="0.4", lw=0.9)
    ax.set_ylabel(ylabel)
    ax.grid(True, axis="y", which="both", alpha=0.3)


def plot_time_distributions(rows: list[dict], path, time_limit: float | None = None) -> Path | None:
    """Planning time of every successful trial, per planner (box + points), one panel per scene
    (``optplan bench tcbirrt`` → ``time_distributions.png``). Returns the path, or None without rows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    if not scenes:
        return None
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.6 * len(scenes), 4.2), squeeze=False)
    for ax, sc in zip(axes[0], scenes):
        rs = [r for r in rows if r["scene"] == sc]
        planners = sorted({r["planner"] for r in rs}, key=lambda x: (x != "tcbirrt", x))
        groups = []
        for p in planners:
            pr = [r for r in rs if r["planner"] == p]
            times = [float(r["cpu_time_s"] if r.get("clock") == "cpu" else r["time_s"]) for r in pr if r["success"]]
            groups.append((p, times, len(pr)))
        clock = "CPU" if rs and rs[0].get("clock") == "cpu" else "wall"
        _boxes(ax, groups, f"planning time per trial [s] ({clock})", limit=time_limit)
        ax.set_title(sc + ("" if time_limit is None else f" (dashed: time limit {time_limit:g} s)"), fontsize=10)
    return save_figure(fig, path, dpi=120)


def plot_warmstart_distributions(rows: list[dict], path) -> Path | None:
    """IPOPT time and iterations of every trial with a plan, warm vs cold, one column per scene
    (``optplan bench warmstart`` → ``time_distributions.png``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    if not scenes:
        return None
    fig, axes = plt.subplots(2, len(scenes), figsize=(4.2 * len(scenes), 7), squeeze=False)
    for c, sc in enumerate(scenes):
        rs = [r for r in rows if r["scene"] == sc and r.get("plan_ok")]
        modes = [m for m in ("warm", "cold") if any(r["mode"] == m for r in rs)]
        for k, (key, lab, log) in enumerate((("opt_time_s", "IPOPT time per trial [s]", True),
                                             ("opt_iterations", "IPOPT iterations per trial", False))):
            groups = []
            for m in modes:
                mr = [r for r in rs if r["mode"] == m]
                vals = [float(r[key]) for r in mr if r.get("success") and r.get(key) is not None]
                groups.append((m, vals, len(mr)))
            _boxes(axes[k, c], groups, lab, log=log)
        axes[0, c].set_title(sc)
    return save_figure(fig, path, dpi=120)
