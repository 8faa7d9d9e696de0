"""What the commands write besides their tables: the HTML view and the PNG figures of a
trajectory, with the same options everywhere (``--html FILE``, ``--plot DIR``)."""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

__all__ = ["write_views", "view_command"]


def write_views(robot, scene, t, q, constrained=None, *, html=None, plot_dir=None, title: str = "optplan trajectory",
                name: str = "plan") -> list[Path]:
    """Write the HTML view to ``html`` and the figures to ``plot_dir`` (either may be None);
    returns the written paths. A missing optional ``viz`` extra is reported on stderr, not raised,
    so that a run's other outputs are kept."""
    out: list[Path] = []
    if html:
        from .html import ViewOptions, VizUnavailable, write_trajectory_html

        try:
            out.append(write_trajectory_html(html, robot, scene, t, q, constrained=constrained,
                                             options=ViewOptions(title=title)))
        except VizUnavailable as exc:
            print(f"optplan: no HTML view written: {exc}", file=sys.stderr)
    if plot_dir:
        from .plan_plots import plot_trajectory

        out.extend(plot_trajectory(robot, scene, t, q, plot_dir, name=name, constrained=constrained))
    return out


def view_command(args) -> int:
    """``optplan view TRAJ.npz [--scene] [--robot] [--html] [--plot DIR] [--playback S]``."""
    from .html import ViewOptions, VizUnavailable, load_trajectory, resolve_scene, view_file

    try:
        p = view_file(args.traj, scene=args.scene, robot=args.robot, out=args.html,
                      options=replace(ViewOptions(), playback_s=args.playback))
    except (ValueError, FileNotFoundError, VizUnavailable) as exc:
        print(f"optplan view: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {p} (open it in a browser: play/pause and the time slider are at the bottom)")
    if args.plot:
        from ..model.robot import RobotModel
        from .plan_plots import plot_trajectory

        tr = load_trajectory(args.traj)
        sc = resolve_scene(args.scene if args.scene is not None else tr.get("scene"))
        rm = RobotModel.from_name(args.robot or tr.get("robot") or sc.robot)
        for f in plot_trajectory(rm, sc, tr["t"], tr["q"], args.plot, name=Path(args.traj).stem,
                                 constrained=tr.get("constrained")):
            print(f"wrote {f}")
    return 0


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
            print(f"optplan: no HTML view written: {exc}", file=sys.stderr)
            break
    return out
