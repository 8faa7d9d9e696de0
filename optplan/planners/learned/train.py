"""Train (or read from the cache) every scene's learned models and report them:
``python -m optplan.planners.learned.train --scene 1,2,3 --out DIR [--epochs N] [--data-task-fraction F]
[--data-region-fraction F] [--no-progress]``.

Per scene: the on-manifold data set, the CVAE (loss curves, held-out reconstruction error, decoded
prior samples' closed-chain residual before/after projection, projection and validity rates next to
uniform joint samples), the latent validity classifier and the learned distance. Writes
``DIR/learned_<scene>.json`` and ``DIR/learned_loss_curves.png`` and prints a table.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["train_scene", "main"]


def train_scene(scene_name: str, epochs: int, progress: bool = True, robot_name: str = "tcbirrt_dual_arm",
                **data: float) -> dict[str, Any]:
    """Build LCBiRRT-LPO for the scene (which trains or loads the CVAE, the classifier and the
    distance network) and return their records; ``data``: ``data_task_fraction`` / ``data_region_fraction``
    (:class:`~.latent_planners.LCBiRRTOptions`)."""
    from ...model.robot import RobotModel
    from ...scene import Scene
    from . import make_learned_planner

    scene = Scene.load(scene_name)
    robot = RobotModel.from_name(scene.robot or robot_name)
    t0 = time.perf_counter()
    c0 = time.process_time()
    pl = make_learned_planner("lcbirrt-lpo", robot, scene, cvae_epochs=epochs, progress=progress, **data)
    cv = pl.cvae
    return {"scene": scene.name, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
            "cvae_epochs": epochs, "data": data,
            "cvae": {"history": cv.history, "metrics": cv.metrics, "file": str(cv.path)},
            "classifier": {**pl.classifier.meta, "file": str(pl.classifier.path)},
            "distance": {**pl.distance.meta, "file": str(pl.distance.path)} if pl.distance is not None else None}


def _plot(records: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for r in records:
        h = r["cvae"]["history"]
        axes[0].plot(h["train_loss"], label=f"{r['scene']} train")
        axes[0].plot(h["val_loss"], "--", label=f"{r['scene']} held out")
        for k, ax in (("classifier", axes[1]), ("distance", axes[2])):
            if r.get(k):
                ax.plot(r[k]["history"]["train_loss"], label=f"{r['scene']} train")
                ax.plot(r[k]["history"]["val_loss"], "--", label=f"{r['scene']} held out")
    for ax, t in zip(axes, ("CVAE loss (recon. + KL)", "latent classifier (BCE)", "learned distance (MSE, standardised)")):
        ax.set_title(t)
        ax.set_xlabel("epoch")
        ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_records(records: list[dict[str, Any]]) -> str:
    """A table of the validation figures (classifier and distance: on the held-out test tenth, with the
    5-nearest-neighbour reference in brackets)."""
    lines = [f"{'scene':13s} {'epochs':>6s} {'train s':>8s} {'recon rms':>9s} {'|h| dec.':>9s} {'|h| proj.':>9s} "
             f"{'proj.':>6s} {'valid':>6s} {'(uniform valid)':>15s} {'clf acc (kNN)':>14s} {'dist corr (kNN)':>16s} "
             f"{'dist rmse':>9s}"]
    for r in records:
        m = r["cvae"]["metrics"]
        d, u = m["decoded_prior"], m["uniform_joints"]
        h = r["cvae"]["history"]
        c = r["classifier"]
        dist = r.get("distance") or {}
        ca, ck = c.get("held_out", {}).get("accuracy", math.nan), c.get("held_out_knn", {}).get("accuracy", math.nan)
        dh, dk = dist.get("held_out", {}), dist.get("held_out_knn", {})
        lines.append(f"{r['scene']:13s} {r['cvae_epochs']:6d} {h['train_time_s'][0]:8.1f} "
                     f"{h['val_recon_rms_rad'][-1]:9.3f} {d['median_residual_before']:9.2e} "
                     f"{d['median_residual_after']:9.1e} {d['projection_rate']:6.2f} {d['valid_rate']:6.2f} "
                     f"{u['valid_rate']:15.3f} {ca:6.3f} ({ck:5.3f}) {dh.get('corr', math.nan):7.3f} "
                     f"({dk.get('corr', math.nan):6.3f}) {dh.get('rmse_m', math.nan):9.3f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.planners.learned.train", description=__doc__)
    ap.add_argument("--scene", default="1,2,3", help="comma-separated scene names or SSPS numbers")
    ap.add_argument("--epochs", type=int, default=None, help="CVAE epochs (default: CVAESettings.epochs)")
    ap.add_argument("--out", default="learned_models", help="report folder")
    ap.add_argument("--data-task-fraction", type=float, default=0.0,
                    help="share of the data from the task-space exploration (ManifoldSampleSettings.task_fraction)")
    ap.add_argument("--data-region-fraction", type=float, default=0.0,
                    help="share of the data from start / goal region walks (ManifoldSampleSettings.region_fraction)")
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args(argv)
    from .cvae import CVAESettings

    epochs = a.epochs if a.epochs is not None else CVAESettings.epochs
    if epochs < 1:
        print(f"--epochs: expected an integer >= 1, got {epochs}", file=sys.stderr)
        return 2
    fr = {"data_task_fraction": a.data_task_fraction, "data_region_fraction": a.data_region_fraction}
    if not all(0.0 <= v <= 1.0 for v in fr.values()) or sum(fr.values()) > 1.0:
        print(f"--data-task-fraction / --data-region-fraction: expected numbers in [0, 1] summing to <= 1, got "
              f"{a.data_task_fraction}, {a.data_region_fraction}", file=sys.stderr)
        return 2
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    for sc in [f"ssps_scene{s.strip()}" if s.strip().isdigit() else s.strip() for s in a.scene.split(",") if s.strip()]:
        r = train_scene(sc, epochs, not a.no_progress, **{k: v for k, v in fr.items() if v})
        (out / f"learned_{r['scene']}.json").write_text(json.dumps(r, indent=1))
        records.append(r)
    _plot(records, out / "learned_loss_curves.png")
    print(format_records(records))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
