"""Jobs solved side by side in forked worker processes: same results, in order, as in one process."""
import os
import time

import numpy as np
import pytest

from optplan.workers import default_workers, run_jobs, shutdown


def _job(scale, offset, x, spin=0.0):
    """A deterministic job that burns ``spin`` seconds of CPU and says where it ran."""
    t = time.process_time()
    while time.process_time() - t < spin:
        pass
    return scale * x + offset, os.getpid()


def test_results_in_job_order_and_identical_to_serial():
    jobs = [(x, 0.05) for x in range(6)]
    par, cpu = run_jobs((2.0, 1.0), _job, jobs, cost=[1.0] * 6, workers=2)
    ser, cpu1 = run_jobs((2.0, 1.0), _job, jobs, cost=[1.0] * 6, workers=1)
    assert [r[0] for r in par] == [r[0] for r in ser] == [2.0 * x + 1.0 for x in range(6)]
    assert cpu1 == 0.0
    pids = {r[1] for r in par}
    assert os.getpid() in pids and len(pids) == 2          # this process took a share, one worker the rest
    assert cpu > 0.1                                        # the worker's CPU time is reported
    shutdown()


def test_longest_jobs_spread_over_processes():
    jobs = [(0, 0.3), (1, 0.3), (2, 0.0), (3, 0.0)]   # the long ones take time: both processes are busy
    out, _ = run_jobs((1.0, 0.0), _job, jobs, cost=[10.0, 9.0, 1.0, 1.0], workers=2)
    assert out[0][1] != out[1][1]                            # the two long jobs run in different processes
    shutdown()


def test_a_free_process_takes_the_next_job_whatever_the_estimates_said():
    """The estimates say jobs 0 and 1 are long; in fact only job 1 is. While one process runs
    job 1, the other runs job 0 and then the two short ones (a fixed split by the estimates would
    have given one of them to the busy process)."""
    jobs = [(0, 0.1), (1, 0.8), (2, 0.02), (3, 0.02)]
    out, _ = run_jobs((1.0, 0.0), _job, jobs, cost=[10.0, 9.0, 1.0, 1.0], workers=2)
    assert [r[0] for r in out] == [0.0, 1.0, 2.0, 3.0]
    assert out[0][1] == out[2][1] == out[3][1] != out[1][1]
    shutdown()


class _LostJobs:
    """A pool that accepts jobs and never starts them (a work item lost between the pool and its
    worker, once seen as a hang of the generalisation benchmark)."""

    def submit(self, *args, **kwargs):
        from concurrent.futures import Future

        return Future()   # pending for ever


def test_a_job_the_pool_never_starts_is_run_here(monkeypatch, caplog):
    import optplan.workers as W

    monkeypatch.setattr(W, "_pool", lambda context, workers: (("lost",), _LostJobs()))
    monkeypatch.setattr(W, "STALL_S", 0.5)
    jobs = [(x, 0.0) for x in range(4)]
    t0 = time.perf_counter()
    with caplog.at_level("WARNING", logger="optplan.workers"):
        out, cpu = run_jobs((2.0, 1.0), _job, jobs, cost=[4.0, 3.0, 2.0, 1.0], workers=2)
    assert [r[0] for r in out] == [2.0 * x + 1.0 for x in range(4)]
    assert {r[1] for r in out} == {os.getpid()} and cpu == 0.0
    assert time.perf_counter() - t0 < 5.0
    assert "did not start" in caplog.text


def _fails(scale, offset, x):
    if x == 1:
        raise ValueError("job 1 failed")
    return _job(scale, offset, x, 0.2)


def test_an_error_in_a_worker_reaches_the_caller():
    with pytest.raises(ValueError, match="job 1 failed"):
        run_jobs((1.0, 0.0), _fails, [(0,), (1,)], cost=[2.0, 1.0], workers=2)
    shutdown()


def test_bad_arguments():
    with pytest.raises(ValueError, match="workers"):
        run_jobs((), _job, [], cost=[], workers=0)
    with pytest.raises(ValueError, match="cost"):
        run_jobs((1.0, 0.0), _job, [(1,)], cost=[], workers=2)
    assert default_workers() in (1, 2)


def test_pipeline_same_trajectory_with_two_processes(tcb):
    from optplan.pipeline import PipelineOptions, run_pipeline
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    scene = Scene.load("ssps_scene1")
    trial = TrialGenerator(tcb, scene).generate(2, 0)
    a = run_pipeline(tcb, scene, trial.q_start, trial.q_goal, PipelineOptions(workers=1), seed=int(trial.seed))
    b = run_pipeline(tcb, scene, trial.q_start, trial.q_goal, PipelineOptions(workers=2), seed=int(trial.seed))
    assert a.success and b.success and len(a.segments) == len(b.segments) >= 2
    np.testing.assert_array_equal(a.q, b.q)
    assert a.iterations == b.iterations
    shutdown()


def _in_daemon(q):
    out, cpu = run_jobs((2.0, 1.0), _job, [(1, 0.0), (2, 0.0)], cost=[1.0, 1.0], workers=2)
    q.put(([r[0] for r in out], {r[1] for r in out} == {os.getpid()}, cpu))


def test_inside_a_daemonic_process_the_jobs_run_there():
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_in_daemon, args=(q,), daemon=True)
    p.start()
    values, all_here, cpu = q.get(timeout=60)
    p.join(timeout=60)
    assert values == [3.0, 5.0] and all_here and cpu == 0.0


_PREPARED: dict[str, int] = {}


def _prepare(scale, offset):
    """A worker's preparation: remembers in its process that it ran (and for which context)."""
    _PREPARED["pid"] = os.getpid()
    _PREPARED["scale"] = int(scale)


def _prepared_job(scale, offset, x):
    return scale * x + offset, os.getpid(), dict(_PREPARED)


def test_started_workers_are_prepared_before_their_jobs_and_reused(monkeypatch):
    """start_workers forks the pool run_jobs then finds (same context objects, same count), and its
    preparation runs in the worker before any job: a job sent there sees what the preparation left."""
    import optplan.workers as W
    from optplan.workers import start_workers

    shutdown(wait=True)                                       # no pool thread left: a fork may be early
    # other tests of this process may have left threads of their own (a progress bar's monitor):
    # the one-thread guard is tested below; here the preparation is
    monkeypatch.setattr(W.threading, "active_count", lambda: 1)
    ctx = (3.0, 1.0)
    assert start_workers(ctx, 1, _prepare) is False          # one process: nothing to start
    assert start_workers(ctx, 2, _prepare) is True
    _PREPARED.clear()                                         # this process never ran it
    jobs = [(x,) for x in range(4)]
    out, _ = run_jobs(ctx, _prepared_job, jobs, cost=[4.0, 3.0, 2.0, 1.0], workers=2)
    assert [r[0] for r in out] == [3.0 * x + 1.0 for x in range(4)]
    in_worker = [r for r in out if r[1] != os.getpid()]
    assert in_worker, "no job ran in the worker"
    for _, pid, prepared in in_worker:
        assert prepared == {"pid": pid, "scale": 3}            # prepared in that very process, first
    for _, pid, prepared in out:
        if pid == os.getpid():
            assert prepared == {}
    with pytest.raises(ValueError, match="workers"):
        start_workers(ctx, 0)
    shutdown()


def test_no_early_fork_while_another_thread_runs():
    """start_workers does not fork while another thread of this process runs (the child would inherit
    the locks that thread holds): False, nothing started, and run_jobs still runs the jobs."""
    import threading

    from optplan.workers import start_workers, workers_started

    shutdown(wait=True)
    stop = threading.Event()
    t = threading.Thread(target=stop.wait, daemon=True)
    t.start()
    try:
        ctx = (5.0, 2.0)
        assert start_workers(ctx, 2, _prepare) is False
        assert not workers_started(ctx, 2)
        out, _ = run_jobs(ctx, _prepared_job, [(1.0,), (2.0,)], cost=[1.0, 1.0], workers=2)
        assert [r[0] for r in out] == [7.0, 12.0]
    finally:
        stop.set()
        t.join()
        shutdown(wait=True)


def test_a_job_sent_early_runs_in_the_started_worker_and_the_rest_are_shared(monkeypatch):
    """send_early hands one job to a worker start_workers started, before the other jobs exist;
    run_jobs counts it as sent (its result in its place, the worker given more when it returns) and
    runs the rest as usual. Without a started worker nothing is sent and run_jobs does it all."""
    import optplan.workers as W
    from optplan.workers import send_early, start_workers

    shutdown(wait=True)
    monkeypatch.setattr(W.threading, "active_count", lambda: 1)
    ctx = (2.0, 0.5)
    assert send_early(ctx, 2, _job, (9.0,)) is None            # no worker started for this context
    assert start_workers(ctx, 2) is True
    assert send_early(ctx, 1, _job, (9.0,)) is None            # one process: nothing to send to
    fut = send_early(ctx, 2, _job, (0.0, 0.3))                 # the long one, before the others are known
    assert fut is not None
    jobs = [(0.0, 0.3), (1.0, 0.0), (2.0, 0.0), (3.0, 0.2), (4.0, 0.0)]
    out, cpu = run_jobs(ctx, _job, jobs, cost=[5.0, 1.0, 1.0, 4.0, 1.0], workers=2, early={0: fut})
    assert [r[0] for r in out] == [2.0 * x + 0.5 for x in range(5)]
    assert out[0][1] != os.getpid()                            # the early job ran in the worker
    assert out[3][1] == os.getpid()                            # the next longest here, meanwhile
    assert cpu > 0.25
    # a single job sent early: still collected (run_jobs uses the worker, not this process alone)
    fut = send_early(ctx, 2, _job, (7.0,))
    out, _ = run_jobs(ctx, _job, [(7.0,)], cost=[1.0], workers=2, early={0: fut})
    assert out[0][0] == 14.5 and out[0][1] != os.getpid()
    shutdown()


def test_pipeline_same_trajectory_with_the_longest_segment_sent_early(tcb, monkeypatch):
    """The pipeline sends its longest constrained segment to the worker started before planning as
    soon as it is shortcut: the same trajectory as one process solving every segment."""
    import optplan.pipeline_workers as PW
    from optplan.pipeline import PipelineOptions, run_pipeline
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    shutdown(wait=True)
    monkeypatch.setattr("optplan.workers.threading.active_count", lambda: 1)
    sent = []
    real = PW.send_segment_early

    def spy(*a, **k):
        fut = real(*a, **k)
        sent.append(fut is not None)
        return fut

    monkeypatch.setattr(PW, "send_segment_early", spy)
    scene = Scene.load("ssps_scene1")
    trial = TrialGenerator(tcb, scene).generate(2, 0)
    a = run_pipeline(tcb, scene, trial.q_start, trial.q_goal, PipelineOptions(workers=1), seed=int(trial.seed))
    assert not any(sent)
    b = run_pipeline(tcb, scene, trial.q_start, trial.q_goal, PipelineOptions(workers=2, early_worker=True),
                     seed=int(trial.seed))
    assert sent and sent[-1], "the two-process run sent no segment early"
    assert a.success and b.success and len(a.segments) == len(b.segments) >= 2
    np.testing.assert_array_equal(a.q, b.q)
    assert a.iterations == b.iterations
    shutdown()


def test_a_new_pool_forks_only_after_the_stopped_pools_threads_have_ended(monkeypatch):
    """A pool shut down without waiting keeps its manager thread for a moment; a fork while that thread holds the old
    pool's lock would leave the new worker blocked on it for ever (the child's garbage collector frees the old pool,
    whose callback takes the lock). The next pool joins those threads before its workers fork."""
    import concurrent.futures.process as cfp

    import optplan.workers as W

    run_jobs((1.0, 0.0), _job, [(0, 0.0), (1, 0.0)], cost=[1.0, 1.0], workers=2)
    old = list(W._POOLS.values())
    threads = [p._executor_manager_thread for p in old]
    assert threads and all(t is not None for t in threads)
    shutdown()                                              # without waiting: the pools are retired
    assert W._RETIRED == threads
    seen: list[bool] = []
    launch = cfp.ProcessPoolExecutor._launch_processes

    def spy(self):                                          # at the new pool's fork
        seen.append(any(t.is_alive() for t in threads))
        return launch(self)

    monkeypatch.setattr(cfp.ProcessPoolExecutor, "_launch_processes", spy)
    out, _ = run_jobs((2.0, 1.0), _job, [(0, 0.0), (1, 0.0)], cost=[1.0, 1.0], workers=2)
    assert [r[0] for r in out] == [1.0, 3.0]
    assert seen == [False] and W._RETIRED == []
    shutdown(wait=True)
