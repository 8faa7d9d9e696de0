"""Accuracy and speed of the analytic IK (``optplan.model.ik_analytic``) of PR2's and Baxter's arms
against Pinocchio's forward kinematics over random joint vectors in the limits.

``python -m optplan.bench.oc_ik [--poses 1000] [--seed 1]`` prints, per arm: the largest pose
error of every returned wrist / full-pose branch (checked with Pinocchio), how often the original
joints are among the branches, the mean number of branches and the time per call, next to the
target (1e-12). Needs ``example-robot-data``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin

__all__ = ["run"]


def run(poses: int = 1000, seed: int = 1) -> list[dict]:
    from ..model.example_robots import load_baxter, load_pr2
    from ..model.ik_analytic import DecoupledArmIK

    rows = []
    for load in (load_pr2, load_baxter):
        r = load()
        for arm in ("left", "right"):
            ik = DecoupledArmIK(r, arm)
            d = r.model.createData()
            rng = np.random.default_rng(seed)
            fid = ik.arm.ee_frame_id
            werr = ferr = 0.0
            miss_w = miss_f = nsol = 0
            tw = tf = 0.0
            for _ in range(poses):
                q = r.random_joints(rng)
                pin.framesForwardKinematics(r.model, d, q)
                M = d.oMf[fid].copy()
                qa = ik.arm_joints(q)
                t = time.perf_counter()
                W = ik.wrist(qa[:4], M.rotation)
                tw += time.perf_counter() - t
                miss_w += not any(np.abs(w - qa[4:]).max() < 1e-9 for w in W)
                for w in W:
                    x = q.copy()
                    x[ik.q_idx[4:]] = w
                    pin.framesForwardKinematics(r.model, d, x)
                    werr = max(werr, float(np.linalg.norm(pin.log3(d.oMf[fid].rotation.T @ M.rotation))))
                t = time.perf_counter()
                S = ik.solve(M.rotation, M.translation, qa[0])
                tf += time.perf_counter() - t
                nsol += len(S)
                miss_f += not any(np.abs(s - qa).max() < 1e-8 for s in S)
                for s in S:
                    x = q.copy()
                    x[ik.q_idx] = s
                    pin.framesForwardKinematics(r.model, d, x)
                    Mi = d.oMf[fid]
                    ferr = max(ferr, float(np.linalg.norm(pin.log3(Mi.rotation.T @ M.rotation))),
                               float(np.linalg.norm(Mi.translation - M.translation)))
            rows.append({"robot": r.name, "arm": arm, "spherical_wrist": ik.spherical, "wrist_offset_m": ik.wrist_offset,
                         "poses": poses, "wrist_max_error": werr, "wrist_original_missed": miss_w,
                         "full_max_error": ferr, "full_original_missed": miss_f, "mean_branches": nsol / poses,
                         "wrist_ms": 1e3 * tw / poses, "full_ms": 1e3 * tf / poses})
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="analytic IK accuracy vs Pinocchio FK (PR2, Baxter)")
    p.add_argument("--poses", type=int, default=1000)
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args(argv)
    print(f"{'arm':14s} {'wrist':>9s} {'offset[m]':>9s} {'wrist err':>9s} {'missed':>6s} {'full err':>9s} {'missed':>6s} "
          f"{'branches':>8s} {'wrist[ms]':>9s} {'full[ms]':>8s}")
    for r in run(a.poses, a.seed):
        print(f"{r['robot'] + ' ' + r['arm']:14s} {('spherical' if r['spherical_wrist'] else 'offset'):>9s} "
              f"{r['wrist_offset_m']:9.1e} {r['wrist_max_error']:9.1e} {r['wrist_original_missed']:6d} "
              f"{r['full_max_error']:9.1e} {r['full_original_missed']:6d} {r['mean_branches']:8.2f} "
              f"{r['wrist_ms']:9.3f} {r['full_ms']:8.2f}")
    print("target: every returned branch reproduces the pose to <= 1e-12 (rad / m) against Pinocchio FK")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
