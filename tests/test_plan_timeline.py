"""The idle-wall estimate of bench.plan_timeline from per-process CPU events."""
from optplan.bench.plan_timeline import _idle_estimate

M, W = 100, 200   # this process's and the worker's pids


def _rows(early: bool, warm_end: float):
    rows = [(0.0, "start", M, 0.05)]
    if early:
        rows += [(0.3, "start_workers (fork)", M, 0.40), (0.31, "worker: preparation starts", W, 0.0),
                 (0.5, "worker: preparation ends", W, warm_end)]
    rows += [(0.6, "segments sent (run_jobs)", M, 0.60),
             (0.61, "segment constrained  starts", M, 0.60), (0.9, "segment constrained  ends", M, 1.10),
             (0.62, "segment constrained  starts", W, warm_end), (1.5, "segment constrained  ends", W, warm_end + 1.0),
             (1.6, "segments back", M, 1.10), (1.7, "command done", M, 1.15)]
    return sorted(rows)


def test_the_longer_chain_sets_the_estimate():
    # late fork: the worker starts when the segments are sent (0.60), 1.0 s of segment, 0.05 s after
    assert abs(_idle_estimate(_rows(False, 0.0), M) - 1.65) < 1e-12
    # early fork, prepared before the segments are sent: the same
    assert abs(_idle_estimate(_rows(True, 0.15), M) - 1.65) < 1e-12
    # early fork, prepared after: the worker's chain is the fork (0.40) + its preparation (0.30)
    assert abs(_idle_estimate(_rows(True, 0.30), M) - (0.40 + 0.30 + 1.0 + 0.05)) < 1e-12
