"""What the commands write besides their tables: the HTML view and the PNG figures of a
trajectory, with the same options everywhere (``--html FILE``, ``--plot DIR``)."""
from __future__ import annotations

import logging
from pathlib import Path

__all__ = ["write_views", "write_method_views"]
log = logging.getLogger(__name__)


def write_views(robot, scene, t, q, constrained=None, *, html=None, plot_dir=None, title: str = "optplan trajectory",
                name: str = "plan") -> list[Path]:
    """Write the HTML view to ``html`` and the figures to ``plot_dir`` (either may be None);
    returns the written paths. A missing optional ``viz`` extra is logged as a warning, not raised,
    so that a run's other outputs are kept."""
    out: list[Path] = []
    if html:
        from .html import ViewOptions, VizUnavailable, write_trajectory_html

        try:
            out.append(write_trajectory_html(html, robot, scene, t, q, constrained=constrained,
                                             options=ViewOptions(title=title)))
        except VizUnavailable as exc:
            log.warning("no HTML view written: %s", exc)
    if plot_dir:
        from .plan_plots import plot_trajectory

        out.extend(plot_trajectory(robot, scene, t, q, plot_dir, name=name, constrained=constrained))
    return out


def write_method_views(robot, trajectories: dict, out_dir, scene=None, title: str = "") -> list[Path]:
    """One HTML view per method: ``trajectories`` maps a method name to ``(t, q)`` or ``(t, q, qd)``
    with ``q`` full configurations or, for a free-floating robot, joints only (the base motion
    then follows from momentum conservation). Writes ``out_dir/<name>.html``; returns the paths
    (none, with a message on stderr, without the ``viz`` extra)."""
    from .html import ViewOptions, VizUnavailable, floating_configurations, write_trajectory_html

    out = []
    for name, tr in trajectories.items():
        t, q = tr[0], tr[1]
        qd = tr[2] if len(tr) > 2 else None
        if robot.is_floating and q.shape[1] == robot.nj:
            q = floating_configurations(robot, t, q, qd)
        try:
            out.append(write_trajectory_html(Path(out_dir) / f"{name}.html", robot, scene, t, q,
                                             options=ViewOptions(title=f"{title}{name}")))
        except VizUnavailable as exc:
            log.warning("no HTML view written: %s", exc)
            break
    return out
