"""Figures of the seed-004 examples in the style of the paper's Fig. 4/7 (joint angular velocities
per method; meeting instants marked) and Fig. 6/9 (base RPY per method), as PNG."""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["plot_case"]

_TITLES = {"quintic": "5th-order polynomial", "ba": "BA", "eba": "EBA", "leader_follower": "leader-follower",
           "fourier": "Fourier near-optimal (IPOPT)", "nlp": "optplan NLP"}


def plot_case(case_result, out_dir, prefix: str | None = None) -> list[Path]:
    """Write ``<prefix>_joint_velocity.png`` and ``<prefix>_base_rpy.png`` into ``out_dir``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prefix = prefix or f"eba_{case_result.case}"
    names = list(case_result.results)
    n = len(names)
    paths = []
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.3 * n), squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        res = case_result.results[name]
        for seg in res.segments:
            ax.set_prop_cycle(None)
            ax.plot(seg.t, np.degrees(seg.qd), lw=0.9)
        if res.meeting_time is not None:
            ax.axvline(res.meeting_time, color="k", ls=":", lw=0.8)
            for seg in res.segments[1:]:
                ax.plot(np.full(seg.qd.shape[1], seg.t[0]), np.degrees(seg.qd[0]), "ko", ms=3)
        ax.set_ylabel("rate [deg/s]")
        ax.set_title(_TITLES.get(name, name), fontsize=9)
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(f"joint angular velocities ({case_result.case.replace('_', ' ')}; 14 joints, A then B)", fontsize=10)
    fig.tight_layout()
    p = out / f"{prefix}_joint_velocity.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.0 * n), squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        t, rpy = case_result.traces[name]
        for i, lab in enumerate(("roll", "pitch", "yaw")):
            ax.plot(t, np.degrees(rpy[:, i]), label=lab)
        rep = case_result.reports[name]
        ax.set_title(f"{_TITLES.get(name, name)} — final ({', '.join(f'{v:+.3g}' for v in rep.final_base_rpy_deg)}) deg",
                     fontsize=9)
        ax.set_ylabel("base [deg]")
    axes[0, 0].legend(fontsize=8, loc="upper left")
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(f"base attitude (RPY, independent simulator; {case_result.case.replace('_', ' ')})", fontsize=10)
    fig.tight_layout()
    p = out / f"{prefix}_base_rpy.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths
