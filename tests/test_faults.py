"""Fault injection: interruption, full disks, a damaged kernel cache and two writers to one folder.

The invariants, whatever the fault and whenever it comes:

* an interrupted command prints ONE line (``interrupted by SIGINT after N of M ...; resume with the
  same command``), exits 128 + the signal number, and leaves no worker process behind;
* every output file is complete or absent (no ``.part`` file left, every npz loads); a result JSON
  never says ``success: true`` without the files it names;
* a write that fails (no space, file-size limit) is one line naming the path, exit 2;
* a damaged cache entry (cut short, garbage, empty) is quarantined with one warning and rebuilt —
  the result is the same as with an intact cache;
* a second run writing to the same benchmark folder is refused; foreign result lines are reported
  by line number and skipped; a summary counts each trial once.

The moments of the signals are drawn from a seeded generator; the commands run in child processes
(``python -m optplan.cli``) with their own process group, as a terminal runs them.
"""
from __future__ import annotations

import json
import logging
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fault_harness import group_members, traceback_lines

PLAN = ["plan", "--scene", "1", "--time-limit", "10"]
BENCH = ["bench", "tcbirrt", "--scene", "1", "--planners", "tcbirrt", "--time-limit", "2", "--no-progress",
         "--no-plot"]
INTERRUPT_LINE = re.compile(r"^optplan( [a-z ]+)?: interrupted by (SIGINT|SIGTERM|SIGHUP)(( after \d+ of \d+ [a-z ]+)?; "
                            r"resume with the same command| before the command started)$")


def _env() -> dict:
    return dict(os.environ, OPTPLAN_BACKGROUND_COMPILE="0", PYTHONUNBUFFERED="1")


def _optplan(args, cwd, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "optplan.cli", *args], cwd=cwd, env=kw.pop("env", _env()),
                          capture_output=True, text=True, timeout=kw.pop("timeout", 300), **kw)


def _interrupt(args, cwd, delay: float, sig: int, to_group: bool) -> dict:
    """Run ``optplan args``, send ``sig`` after ``delay`` s; exit code, stderr, the processes of its
    group alive 2 s after it ended (the budget for stopping workers)."""
    p = subprocess.Popen([sys.executable, "-m", "optplan.cli", *args], cwd=cwd, env=_env(), text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    time.sleep(delay)
    sent = p.poll() is None
    if sent:
        (os.killpg if to_group else os.kill)(p.pid, sig)
    t0 = time.monotonic()
    try:
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:   # pragma: no cover - a hang: fail below, leave nothing behind
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
    time.sleep(2.0)
    left = group_members(p.pid, cwd)
    for pid in left:   # pragma: no cover - only when the invariant fails
        os.kill(pid, signal.SIGKILL)
    return {"rc": p.returncode, "stderr": err, "orphans": left, "sent": sent, "exit_s": time.monotonic() - t0 - 2.0}


def _assert_interrupted(r: dict, sig: int) -> None:
    """Exit 128 + signal within the watchdog's grace time, and stderr is the one line."""
    from optplan.interrupt import GRACE_S

    assert r["rc"] == 128 + sig, (r["rc"], r["stderr"][-2000:])
    lines = r["stderr"].strip().splitlines()
    assert len(lines) == 1 and INTERRUPT_LINE.match(lines[0]), r["stderr"]
    assert r["exit_s"] < GRACE_S + 1.0, r["exit_s"]


def _assert_outputs_complete(d: Path) -> None:
    """No partial file; every npz loads; a JSON that says success names files that exist and load."""
    assert not list(d.glob("*.part*")) and not list(d.glob(".*.part*")), sorted(p.name for p in d.iterdir())
    for npz in d.glob("*.npz"):
        with np.load(npz, allow_pickle=False) as z:
            assert z["q"].ndim == 2 and len(z["t"]) == len(z["q"])
    js = d / "out.json"
    if js.exists():
        rec = json.loads(js.read_text())
        if rec["success"]:
            assert rec["files"] and all((d / f).exists() for f in rec["files"]), rec["files"]
        else:
            assert rec.get("status") in ("interrupted", "error", None)


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """One uninterrupted ``optplan plan`` (fills the kernel cache, so later runs take a few
    seconds): its result JSON names the trajectory it wrote."""
    d = tmp_path_factory.mktemp("plan_ref")
    p = _optplan(PLAN + ["--json", "out.json", "--save", "traj.npz"], d)
    assert p.returncode == 0, p.stderr[-2000:]
    rec = json.loads((d / "out.json").read_text())
    assert rec["success"] and rec["files"] == ["traj.npz"]
    _assert_outputs_complete(d)
    return d


@pytest.mark.parametrize("sig, to_group, extra, seed", [
    (signal.SIGINT, True, [], 1),                        # Ctrl-C in a terminal: the whole group
    (signal.SIGTERM, False, ["--workers", "2"], 2),      # kill PID: the main process only, forked workers
])
def test_plan_interrupted_at_a_random_moment(warm, tmp_path, sig, to_group, extra, seed):
    delay = float(np.random.default_rng(seed).uniform(0.5, 2.5))
    r = _interrupt(PLAN + extra + ["--json", "out.json", "--save", "traj.npz"], tmp_path, delay, sig, to_group)
    assert traceback_lines(r["stderr"]) == 0, r["stderr"][-3000:]
    assert not r["orphans"], f"processes left after {delay:.2f} s + {sig!r}: {r['orphans']}"
    if r["rc"] in (0, 1):   # it ended before the signal: a complete run
        assert (tmp_path / "out.json").exists()
    else:
        _assert_interrupted(r, sig)
        if (tmp_path / "out.json").exists():
            assert json.loads((tmp_path / "out.json").read_text())["status"] == "interrupted"
    _assert_outputs_complete(tmp_path)


_SIGNAL_AFTER_RECORD = """
import os, signal, sys
import optplan.cli_plan as cp
from optplan import cli
write = cp._write_json
def write_then_signal(path, data):
    write(path, data)
    if data.get("success"):          # the success record is on disk: the signal comes now
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(10000):
            pass
cp._write_json = write_then_signal
sys.argv = ["optplan", *sys.argv[1:]]
sys.exit(cli.main())
"""


def test_a_signal_after_the_success_record_leaves_a_complete_run(warm, tmp_path):
    """A SIGTERM arriving once the record that says success is written (while the idle workers are stopped, as the
    process ends) does not turn the run into an interruption beside that record: exit 0, no interruption line, the
    record and the files it names complete."""
    p = subprocess.run([sys.executable, "-c", _SIGNAL_AFTER_RECORD, *PLAN, "--json", "out.json", "--save", "traj.npz"],
                       cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, (p.returncode, p.stderr[-2000:])
    assert "interrupted" not in p.stderr and traceback_lines(p.stderr) == 0, p.stderr[-2000:]
    rec = json.loads((tmp_path / "out.json").read_text())
    assert rec["success"] and rec["files"] == ["traj.npz"], rec
    _assert_outputs_complete(tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6))
def test_plan_interrupted_many_moments(warm, tmp_path, seed):
    rng = np.random.default_rng(100 + seed)
    sig = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP][seed % 3]
    r = _interrupt(PLAN + ["--workers", "2", "--json", "out.json", "--save", "traj.npz"], tmp_path,
                   float(rng.uniform(0.2, 3.5)), sig, to_group=bool(seed % 2))
    assert traceback_lines(r["stderr"]) == 0 and not r["orphans"]
    if r["rc"] not in (0, 1):
        _assert_interrupted(r, sig)
    _assert_outputs_complete(tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("seed, sig", [(7, signal.SIGTERM), (8, signal.SIGINT)])
def test_bench_with_a_worker_pool_interrupted(warm, tmp_path, seed, sig):
    """``--jobs 2`` (spawned workers): SIGTERM to the main process or Ctrl-C to the group, at a
    seeded moment (also while the workers start): one line, no worker left."""
    out = tmp_path / "b"
    r = _interrupt(BENCH + ["--trials", "4", "--jobs", "2", "--out", str(out)], tmp_path,
                   float(np.random.default_rng(seed).uniform(0.3, 3.0)), sig, to_group=sig == signal.SIGINT)
    assert traceback_lines(r["stderr"]) == 0 and not r["orphans"], r
    if r["rc"] != 0:
        _assert_interrupted(r, sig)
    for line in (out / "results.jsonl").read_text().splitlines() if (out / "results.jsonl").exists() else []:
        assert json.loads(line)["scene"] == "ssps_scene1"


def test_bench_interrupted_then_resumed(warm, tmp_path):
    """Ctrl-C during a small benchmark: one line with the count of finished trial runs; every line
    written is a complete result; the same command resumes and ends with each trial once."""
    out = tmp_path / "b"
    args = BENCH + ["--trials", "3", "--out", str(out)]
    r = _interrupt(args, tmp_path, float(np.random.default_rng(3).uniform(1.0, 2.5)), signal.SIGINT, True)
    assert traceback_lines(r["stderr"]) == 0 and not r["orphans"], r["stderr"]
    n_before = len((out / "results.jsonl").read_text().splitlines()) if (out / "results.jsonl").exists() else 0
    if r["rc"] == 130:
        _assert_interrupted(r, signal.SIGINT)
        assert f"after {n_before} of 3 trial runs" in r["stderr"] or "after" not in r["stderr"], (r, n_before)
    else:
        assert r["rc"] == 0, r["stderr"]
    p = _optplan(args, tmp_path)
    assert p.returncode == 0, p.stderr
    rows = [json.loads(s) for s in (out / "results.jsonl").read_text().splitlines()]
    assert sorted(r["trial"] for r in rows) == [0, 1, 2]
    summ = json.loads((out / "summary.json").read_text())
    assert summ["ssps_scene1"]["planners"]["tcbirrt"]["n"] == 3


def test_save_past_the_file_size_limit_is_one_line_and_no_torn_file(warm, tmp_path):
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        import resource

        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))   # the npz is ~280 kB

    p = _optplan(PLAN + ["--json", "out.json", "--save", "traj.npz"], tmp_path, preexec_fn=limit)
    assert p.returncode == 2 and traceback_lines(p.stderr) == 0, p.stderr
    # (the limit also cuts the C code the kernels are generated as: those compile failures are warnings)
    err = [ln for ln in p.stderr.splitlines() if ln.startswith("optplan plan: error:")]
    assert err == ["optplan plan: error: cannot write 'traj.npz': File too large (EFBIG)"], p.stderr
    assert not (tmp_path / "traj.npz").exists()
    rec = json.loads((tmp_path / "out.json").read_text())
    assert rec["success"] is False and rec["files"] == []
    _assert_outputs_complete(tmp_path)


def test_json_to_a_full_device_is_one_line(tmp_path):
    p = _optplan(["models", "info", "tcbirrt_dual_arm", "--json", "/dev/full"], tmp_path)
    assert p.returncode == 2 and traceback_lines(p.stderr) == 0
    assert p.stderr.strip().splitlines() == [
        "optplan models info: error: cannot write '/dev/full': No space left on device (ENOSPC)"]


def test_atomic_writes_keep_the_old_file_on_failure(tmp_path):
    from optplan._io import OutputError, atomic_path, write_json

    f = tmp_path / "a.json"
    write_json(f, {"v": 1})
    with pytest.raises(RuntimeError), atomic_path(f) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted while writing")
    assert json.loads(f.read_text()) == {"v": 1} and sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]
    with pytest.raises(OutputError, match=r"cannot write .*missing/b.json.*No such file"):
        write_json(tmp_path / "missing" / "b.json", {})


def test_cache_setting_that_is_a_file_is_one_line(tmp_path):
    bad = tmp_path / "cache"
    bad.write_text("")
    p = _optplan(PLAN, tmp_path, env=dict(_env(), OPTPLAN_CACHE=str(bad)))
    assert p.returncode == 2 and traceback_lines(p.stderr) == 0
    assert p.stderr.strip().splitlines() == [f"optplan plan: error: OPTPLAN_CACHE={str(bad)!r}: is a file, expected "
                                             "a folder for compiled kernels (point OPTPLAN_CACHE at a folder, or "
                                             "unset it for ~/.cache/optplan)"]


_KERNEL = """
import logging, sys
import casadi as ca, numpy as np
from optplan.codegen import CompiledFunction, compile_function
logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
x = ca.SX.sym("x", 3)
f = ca.Function("fault_kernel", [x], [ca.sumsqr(x) + ca.sin(x[0]) * x[2]])
cf = compile_function(f)
assert isinstance(cf, CompiledFunction), type(cf)
xs = np.random.default_rng(7).normal(size=(5, 3))
print(max(abs(float(cf(v)[0][0]) - float(f(v))) for v in xs))
"""


@pytest.mark.parametrize("damage", ["half", "garbage", "empty", "half-without-record"])
def test_damaged_compiled_kernel_is_quarantined_and_rebuilt(tmp_path, damage):
    """A kernel library cut to half its size (which SIGBUSes a process that loads it), garbage or
    empty: the next run warns once, moves it to quarantine/, rebuilds it, and computes the same
    values as the interpreted function; the run after that is silent."""
    env = dict(_env(), OPTPLAN_CACHE=str(tmp_path / "cache"))

    def run():
        return subprocess.run([sys.executable, "-c", _KERNEL], env=env, capture_output=True, text=True, timeout=120)

    first = run()
    assert first.returncode == 0 and float(first.stdout) < 1e-12, first.stderr
    (lib,) = (tmp_path / "cache").glob("fault_kernel_*.so")
    data = lib.read_bytes()
    body = {"garbage": b"\x7fELF" + bytes(np.random.default_rng(5).integers(0, 256, 4096, dtype=np.uint8)),
            "empty": b""}.get(damage, data[:len(data) // 2])
    lib.write_bytes(body)
    if damage == "half-without-record":   # a cache written before records existed: the ELF check
        lib.with_name(lib.name + ".sha256").unlink()
    second, third = run(), run()
    assert second.returncode == 0 and float(second.stdout) < 1e-12, (second.returncode, second.stderr)
    warnings = [ln for ln in second.stderr.splitlines() if ln.startswith("WARNING")]
    assert len(warnings) == 1 and "is damaged" in warnings[0] and "quarantine" in warnings[0], second.stderr
    assert len(list((tmp_path / "cache" / "quarantine").iterdir())) >= 1
    assert third.returncode == 0 and third.stderr == "" and float(third.stdout) < 1e-12
    assert lib.read_bytes() == data   # rebuilt from the same C code


def test_damaged_kernel_library_of_the_segment_nlp(tmp_path, monkeypatch, tcb, caplog):
    """The NLP's kernels (``KernelCache``): a library an earlier run left cut short is not loaded
    but quarantined and compiled again; the rebuilt kernel gives the symbolic kernel's values.
    (Compiled without loading it here: a library loaded by this process stays mapped.)"""
    import casadi as ca

    from optplan.problem.kernel_compiler import compile_library
    from optplan.problem.kernels import KernelCache

    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    kc = KernelCache(tcb)
    q = ca.SX.sym("q", tcb.nj)
    fn = ca.Function("fault_nlp_kernel", [q, ca.SX.sym("n", 3), ca.SX.sym("s")], [ca.sin(q[:3]) * q[0]])
    lib = kc._dir / "fault_nlp_kernel-O1.so"
    assert compile_library(fn, lib, "-O1") and lib.with_name(lib.name + ".sha256").exists()
    lib.write_bytes(lib.read_bytes()[:1000])
    with caplog.at_level(logging.WARNING, logger="optplan.cache"):
        assert kc.compiled(fn, build=False) is None   # only load: the damaged one is refused
        again = kc.compiled(fn)                         # build: compiled afresh
    assert caplog.text.count("is damaged") == 1 and len(list((tmp_path / "quarantine").iterdir())) == 2
    x = np.random.default_rng(1).normal(size=tcb.nj)
    assert again is not fn and np.allclose(np.asarray(again(x, np.zeros(3), 0.0)), np.asarray(fn(x, np.zeros(3), 0.0)))


def test_second_writer_to_a_bench_folder_is_refused(tmp_path):
    from optplan.bench.folder import LOCK_NAME, folder_lock
    from optplan.errors import FolderBusyError

    with folder_lock(tmp_path / "b"):
        assert (tmp_path / "b" / LOCK_NAME).read_text().strip() == str(os.getpid())
        with pytest.raises(FolderBusyError, match=rf"--out '{tmp_path / 'b'}': another optplan run \(pid {os.getpid()}\)"):
            with folder_lock(tmp_path / "b"):
                pass   # pragma: no cover
    with folder_lock(tmp_path / "b"):   # released with its holder
        pass


def test_two_bench_commands_on_one_folder(warm, tmp_path):
    out = tmp_path / "same"
    first = subprocess.Popen([sys.executable, "-m", "optplan.cli", *BENCH, "--trials", "2", "--out", str(out)],
                             cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lock = out / ".optplan.lock"
    t0 = time.monotonic()
    while not (lock.exists() and lock.read_text().strip()) and time.monotonic() - t0 < 60:
        time.sleep(0.05)
    # the first run holds the folder while the second starts: paused (alive, lock kept) so that a
    # fast first run cannot end before the second has imported
    os.kill(first.pid, signal.SIGSTOP)
    try:
        second = _optplan(BENCH + ["--trials", "2", "--out", str(out)], tmp_path)
    finally:
        os.kill(first.pid, signal.SIGCONT)
    first.communicate(timeout=300)
    assert first.returncode == 0
    assert second.returncode == 2 and traceback_lines(second.stderr) == 0
    assert second.stderr.strip() == (f"optplan bench tcbirrt: error: --out {str(out)!r}: another optplan run "
                                     f"(pid {first.pid}) is writing to this folder; wait for it to end or choose "
                                     "another --out")
    rows = [json.loads(s) for s in (out / "results.jsonl").read_text().splitlines()]
    assert sorted(r["trial"] for r in rows) == [0, 1]


def test_foreign_result_lines_are_reported_and_skipped(tmp_path, caplog):
    from optplan.bench.folder import dedupe, read_result_lines

    good = {"scene": "s", "trial": 0, "planner": "p", "success": True}
    p = tmp_path / "results.jsonl"
    p.write_text("\n".join([json.dumps(good), "[1, 2]", '"hello"', json.dumps({**good, "trial": "x"}),
                            "{not json", json.dumps({**good, "success": False})]) + "\n")
    with caplog.at_level(logging.WARNING, logger="optplan.bench.folder"):
        rows = read_result_lines(p)
    assert len(rows) == 2
    for n, what in ((2, "a JSON list"), (3, "a JSON str"), (4, "trial 'x' is not an integer"), (5, "not JSON")):
        assert f"results.jsonl line {n}: not a result line ({what}" in caplog.text
    assert "line 1:" not in caplog.text and "line 6:" not in caplog.text
    one = dedupe(rows, lambda r: (r["scene"], r["trial"], r["planner"]))
    assert one == [{**good, "success": False}]   # each trial once, the last line written wins


def test_bench_summary_counts_each_trial_once(warm, tmp_path):
    """A folder with a duplicated line (two writers of an older version) and foreign lines: the
    resumed run reports them by line number and its summary counts 2 trials, not 3."""
    out = tmp_path / "b"
    first = _optplan(BENCH + ["--trials", "2", "--out", str(out)], tmp_path)
    assert first.returncode == 0, first.stderr
    lines = (out / "results.jsonl").read_text().splitlines()
    (out / "results.jsonl").write_text("\n".join(lines + [lines[0], "[1, 2]", '"hello"']) + "\n")
    p = _optplan(BENCH + ["--trials", "2", "--out", str(out)], tmp_path)
    assert p.returncode == 0 and traceback_lines(p.stderr) == 0, p.stderr
    assert "results.jsonl line 4: not a result line" in p.stderr and "results.jsonl line 5:" in p.stderr
    summ = json.loads((out / "summary.json").read_text())
    assert summ["ssps_scene1"]["planners"]["tcbirrt"]["n"] == 2
    assert re.search(r"tcbirrt +[0-2]/2 ", p.stdout), p.stdout


def test_an_output_folder_without_room_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    """Less than ``MIN_FREE_BYTES`` free where an output goes: exit 2 with one line, before any work."""
    from types import SimpleNamespace

    from optplan import _io
    from optplan.cli import main

    monkeypatch.setattr(_io.os, "statvfs", lambda p: SimpleNamespace(f_bavail=100, f_frsize=4096))
    t0 = time.perf_counter()
    assert main(["bench", "tcbirrt", "--scene", "1", "--trials", "1", "--out", str(tmp_path / "o")]) == 2
    assert time.perf_counter() - t0 < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"optplan bench tcbirrt: error: --out {str(tmp_path)!r}: only 0.4 MB free on its file system, "
                   f"expected at least {_io.MIN_FREE_BYTES / 1e6:.1f} MB"]
    assert not (tmp_path / "o").exists()


def test_an_interrupted_kernel_compile_leaves_no_compiler_process(tmp_path, monkeypatch):
    """The C compiler runs in its own process group: an interruption while it runs ends the
    driver and its children (cc1, as, ld), and leaves no partial library."""
    import subprocess as sp

    from optplan import codegen

    if codegen.c_compiler() is None:
        pytest.skip("no C compiler")
    body = "\n".join(f"  x = x * 1.0000001 + {i}.0 / (x + {i + 1}.0);" for i in range(40000))
    src = tmp_path / "big.c"
    src.write_text(f"double big(double x) {{\n{body}\n  return x;\n}}\n")
    started: list[int] = []

    class Recording(sp.Popen):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            started.append(self.pid)

    class Stop(BaseException):
        pass

    def stop(signum, frame):
        raise Stop

    monkeypatch.setattr(codegen.subprocess, "Popen", Recording)
    old = signal.signal(signal.SIGALRM, stop)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.5)
        with pytest.raises(Stop):
            codegen.build_library(src, tmp_path / "big.so", "-O2")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    time.sleep(0.3)

    def compiling() -> list[int]:   # live processes with the source file on their command line (cc, cc1)
        out = []
        for d in Path("/proc").iterdir():
            try:
                if d.name.isdigit() and str(src).encode() in (d / "cmdline").read_bytes() \
                        and (d / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                    out.append(int(d.name))
            except OSError:
                continue
        return out

    assert started and compiling() == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.c"]
