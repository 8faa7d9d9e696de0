"""The TCBiRRT paper's Tables 2-3 and Fig. 6 from a benchmark run, beside the paper's figures.

* Table 2: success rate at the time limit (Eq. 9 at t = limit; the paper's limit is 1000 s).
* Table 3: mean ± standard deviation of the n_min fastest successful times (Eq. 10-11; n_min = 40,
  30, 15 per 100 trials on scenes 1-3, scaled with the number of trials), only for planners with at
  least n_min successes ("/" otherwise, as in the paper).
* Fig. 6: p(t) of every planner, one panel per scene, linear time axis up to the limit.

The seven planners of the paper, in its table order: :data:`PAPER_ORDER`. Our figures come from our
reconstruction (robot mounting, scene geometry, machine, time limit), see ``docs/planners.md``.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["PAPER", "PAPER_ORDER", "PAPER_LABELS", "expand_planners", "format_tables", "plot_fig6", "success_curve"]

PAPER: dict[str, dict[str, tuple[float, float | None, float | None]]] = {  # the TCBiRRT paper Tables 2-3 (t = 1000 s; times: mean ± std of the n_min fastest)
    "tcbirrt": {"ssps_scene1": (0.94, 0.82, 0.65), "ssps_scene2": (0.96, 2.12, 0.94), "ssps_scene3": (0.93, 0.87, 0.38)},
    "cbirrt2": {"ssps_scene1": (0.25, None, None), "ssps_scene2": (0.18, None, None), "ssps_scene3": (0.02, None, None)},
    "precomputed-graph": {"ssps_scene1": (0.22, None, None), "ssps_scene2": (0.22, None, None),
                          "ssps_scene3": (0.02, None, None)},
    "constrained-prm": {"ssps_scene1": (0.42, 395.19, 269.03), "ssps_scene2": (0.30, 398.50, 287.88),
                        "ssps_scene3": (0.18, 571.74, 288.31)},
    "latent-sampling": {"ssps_scene1": (0.40, 474.61, 346.93), "ssps_scene2": (0.38, 301.33, 274.02),
                        "ssps_scene3": (0.01, None, None)},
    "lcbirrt": {"ssps_scene1": (0.65, 117.65, 108.59), "ssps_scene2": (0.37, 386.24, 244.36),
                "ssps_scene3": (0.09, None, None)},
    "lcbirrt-lpo": {"ssps_scene1": (0.92, 42.89, 45.89), "ssps_scene2": (0.63, 179.27, 130.62),
                    "ssps_scene3": (0.15, 479.16, 301.04)},
}


def _time_of(r: dict) -> float:
    return float(r["cpu_time_s"] if r.get("clock") == "cpu" else r["time_s"])


def success_curve(times: list[float], n: int, ts) -> list[float]:
    """p(t) = n_t / n (Eq. 9): fraction of the n trials solved within t."""
    arr = np.sort(np.asarray(times, float))
    if n < 1:   # no trials: the fraction is undefined
        return [float("nan") for _ in ts]
    return [float(np.searchsorted(arr, t, side="right")) / n for t in ts]


#: the paper's Table 2 order (our planner names)
PAPER_ORDER = ("cbirrt2", "precomputed-graph", "constrained-prm", "latent-sampling", "lcbirrt", "lcbirrt-lpo",
               "tcbirrt")
PAPER_LABELS = {"cbirrt2": "CBiRRT2", "precomputed-graph": "Precomputed Graph", "constrained-prm": "Constrained PRM",
                "latent-sampling": "Latent Sampling", "lcbirrt": "LCBiRRT", "lcbirrt-lpo": "LCBiRRT-LPO",
                "tcbirrt": "TCBiRRT"}


def expand_planners(specs: list[str]) -> list[str]:
    """``"all"`` → the paper's seven planners (:data:`PAPER_ORDER`); other specs unchanged, duplicates dropped."""
    out: list[str] = []
    for s in specs:
        s = s.strip()
        for p in (PAPER_ORDER if s.lower() == "all" else (s,) if s else ()):
            if p not in out:
                out.append(p)
    return out


def _scenes(summ: dict[str, Any]) -> list[str]:
    return list(summ)


def format_tables(summ: dict[str, Any], time_limit: float, clock: str = "cpu") -> str:
    """Tables 2 and 3 of ``summarize(rows)`` with the paper's figures in brackets."""
    scenes = _scenes(summ)
    planners = _ordered({p for s in scenes for p in summ[s]["planners"]})
    w = 22
    head = f"{'planner':26s}" + "".join(f"{s:>{w}s}" for s in scenes)
    lines = [f"Table 2: success rate at t = {time_limit:g} s ({clock} clock), ours (paper at 1000 s)", head]
    for p in planners:
        cells = []
        for s in scenes:
            d = summ[s]["planners"].get(p)
            pp = PAPER.get(_base(p), {}).get(s)
            ours = "-" if d is None else f"{d['success_rate']:.2f} ({d['successes']}/{d['n']})"
            cells.append(f"{ours} [{pp[0]:.2f}]" if pp else ours)
        lines.append(f"{_label(p):26s}" + "".join(f"{c:>{w}s}" for c in cells))
    nmins = ", ".join(f"{s} {summ[s]['n_min']}" for s in scenes)
    lines += ["", f"Table 3: mean ± std of the n_min fastest successful times [s] (n_min: {nmins}), ours [paper]",
              head]
    for p in planners:
        cells = []
        for s in scenes:
            d = summ[s]["planners"].get(p)
            pp = PAPER.get(_base(p), {}).get(s)
            ours = "-" if d is None else ("/" if d.get("mean_fastest_nmin_s") is None else
                                          f"{d['mean_fastest_nmin_s']:.2f}±{d['std_fastest_nmin_s']:.2f}")
            paper = "" if pp is None else (" [/]" if pp[1] is None else f" [{pp[1]:.4g}±{pp[2]:.4g}]")
            cells.append(ours + paper)
        lines.append(f"{_label(p):26s}" + "".join(f"{c:>{w + 6}s}" for c in cells))
    lines += [f"{_label(p)}: {p}" for p in planners if ":" in p]   # the options behind a marked row
    return "\n".join(lines)


def _base(spec: str) -> str:
    """The planner's name in a spec (``"lcbirrt:data_task_fraction=1.0"`` → ``"lcbirrt"``)."""
    return spec.split(":", 1)[0].strip().lower()


def _label(spec: str) -> str:
    """The paper's name of a spec's planner; marked ``*`` when the spec sets options."""
    base = _base(spec)
    return PAPER_LABELS.get(base, base) + (" *" if ":" in spec else "")


def _ordered(specs: set[str]) -> list[str]:
    """Specs in the paper's table order (by planner name), then the others, by name."""
    rank = {p: i for i, p in enumerate(PAPER_ORDER)}
    return sorted(specs, key=lambda p: (rank.get(_base(p), len(rank)), p))


def plot_fig6(rows: list[dict[str, Any]], path: Any, time_limit: float) -> None:
    """Fig. 6: p(t) (Eq. 9) per scene, every planner, linear time axis from 0 to the limit."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    if not scenes:
        return
    fig, axes = plt.subplots(1, len(scenes), figsize=(5 * len(scenes), 4), squeeze=False)
    ts = np.linspace(0.0, time_limit, 400)
    for ax, sc in zip(axes[0], scenes):
        rs = [r for r in rows if r["scene"] == sc]
        present = {r["planner"] for r in rs}
        for p in _ordered(present):
            pr = [r for r in rs if r["planner"] == p]
            times = [_time_of(r) for r in pr if r["success"]]
            ax.step(ts, success_curve(times, len(pr), ts), where="post", label=f"{_label(p)} ({len(pr)})",
                    lw=2.2 if p == "tcbirrt" else 1.3)
        ax.set_xlim(0, time_limit)
        ax.set_ylim(-0.02, 1.02)
        clock = rs[0].get("clock", "wall") if rs else "wall"
        ax.set_xlabel(f"planning time t [s]{' (CPU)' if clock == 'cpu' else ''}")
        ax.set_ylabel("success rate p(t)")
        ax.set_title(sc.replace("ssps_scene", "Scene "))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower right", fontsize=7)
    fig.suptitle(f"p(t), Eq. 9 (the TCBiRRT paper's Fig. 6), time limit {time_limit:g} s"
                 + ("" if math.isclose(time_limit, 1000.0) else " (paper: 1000 s)"))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
