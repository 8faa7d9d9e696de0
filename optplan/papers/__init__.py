"""Reproductions of the source papers, one subpackage per paper key (see docs/papers.md):

* :mod:`optplan.papers.eba` — base-attitude restoration of a dual-arm free-floating robot (BA, EBA,
  quintic, leader-follower, Fourier near-optimal and optplan's NLP);
* :mod:`optplan.papers.dshdasr` — target transposition by the discrete-serpentine dual-arm robot with
  the space-arc equivalent kinematics;
* :mod:`optplan.papers.spline_rrt` — Spline-RRT*: coordinated task-space RRT*, quartic splines and
  resolved-rate tracking on the free-floating base, and optplan's optimized variant.

The TCBiRRT and OC-RRT planners are library planners (:mod:`optplan.planners`); their paper
benchmarks are in :mod:`optplan.bench`. These subpackages import the library; the library never
imports them. Subpackages are imported on demand; this package imports nothing itself.
"""
