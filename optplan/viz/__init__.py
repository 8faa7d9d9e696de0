"""Matplotlib figures (PNG)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["save_figure", "plot_joint_trajectory"]


def save_figure(fig, path: str | Path, dpi: int = 110) -> Path:
    """Lay out ``fig``, write it to ``path`` (PNG at ``dpi``), close it; returns the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    p = Path(path)
    from .._io import atomic_path

    with atomic_path(p) as tmp:   # complete or absent
        fig.savefig(tmp, dpi=dpi)
    plt.close(fig)
    return p


def plot_joint_trajectory(sol, out_dir: str | Path, name: str) -> list[Path]:
    """Joint positions and velocities of a Solution, sampled exactly, as ``<name>_joints.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t = np.linspace(sol.t[0], sol.t[-1], 10 * (len(sol.t) - 1) + 1)
    s = sol.sample(t)
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    ax[0].plot(t, np.degrees(s["q"]))
    ax[0].set_ylabel("joint angle [deg]")
    ax[1].plot(t, np.degrees(s["qd"]))
    ax[1].set_ylabel("joint rate [deg/s]")
    ax[1].set_xlabel("t [s]")
    return [save_figure(fig, out / f"{name}_joints.png", dpi=120)]
