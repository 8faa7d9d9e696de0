"""Fault harness: reproduce the interruption, disk, cache and concurrency faults of the command line
and count which of them still show their symptom.

Run as ``python tests/fault_harness.py [--pythonpath DIR] [--seed N]``: every case runs ``optplan`` in a
child process (``python -m optplan.cli`` with ``DIR`` first on ``sys.path``, so an exported older tree
can be measured the same way) and prints one row: the case, whether the symptom was seen, and what
was seen (exit status, lines on stderr, files left behind). ``tests/test_faults.py`` asserts the
same invariants; this script only counts them.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

_PLAN = ["plan", "--scene", "1", "--time-limit", "10"]
# runs long enough (~10 s) for a signal at 1-3 s to land mid-run, now that scene 1 plans in ~2 s
_PLAN_LONG = ["plan", "--scene", "hard_bay", "--time-limit", "10"]
_BENCH = ["bench", "tcbirrt", "--scene", "1", "--trials", "4", "--planners", "tcbirrt", "--time-limit", "2",
          "--no-progress", "--no-plot"]


def _env(pythonpath: str | None, cache: Path) -> dict:
    env = dict(os.environ, OPTPLAN_CACHE=str(cache), OPTPLAN_BACKGROUND_COMPILE="0", PYTHONUNBUFFERED="1")
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _cmd(args: list[str]) -> list[str]:
    return [sys.executable, "-m", "optplan.cli", *args]


def group_members(pgid: int, cwd: Path | None = None) -> list[int]:
    """Live processes of process group ``pgid`` (zombies excluded) and, with ``cwd``, every live
    process working in that folder or below (children that left the group, e.g. a compiler in its
    own session, still inherit the command's working folder)."""
    out = []
    inside = str(Path(cwd).resolve()) if cwd is not None else None
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        try:
            stat = (d / "stat").read_text()
            fields = stat[stat.rfind(")") + 2:].split()
            if fields[0] == "Z":
                continue
            if int(fields[2]) == pgid:
                out.append(int(d.name))
            elif inside is not None and (os.readlink(d / "cwd") + "/").startswith(inside + "/"):
                out.append(int(d.name))
        except (OSError, IndexError, ValueError):
            continue
    return out


def run_interrupted(args: list[str], env: dict, delay: float, sig: int, *, cwd: Path, group: bool = True
                    ) -> dict:
    """Start ``optplan args``, send ``sig`` after ``delay`` s (to the whole process group, as a terminal's
    Ctrl-C does, or to the main process only), and return exit code, stderr, time to exit and the
    processes of its group still alive 2 s after the main process ended."""
    p = subprocess.Popen(_cmd(args), env=env, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         start_new_session=True, text=True)
    time.sleep(delay)
    t0 = time.monotonic()
    sent = p.poll() is None
    if sent:
        (os.killpg if group else os.kill)(p.pid, sig)
    try:
        out, err = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, err = p.communicate()
    t_exit = time.monotonic() - t0
    time.sleep(2.0)
    left = group_members(p.pid, cwd)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    return {"rc": p.returncode, "stdout": out, "stderr": err, "exit_s": t_exit, "orphans": left, "sent": sent}


def _untested(r: dict) -> tuple[None, str] | None:
    """A run that ended before its signal was sent tests nothing (neither ok nor a symptom)."""
    if r["sent"]:
        return None
    return None, f"exit {r['rc']}: finished before the signal was sent (inconclusive)"


def _limit_fsize(nbytes: int):
    def f():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))
    return f


def traceback_lines(text: str) -> int:
    return sum(1 for ln in text.splitlines() if ln.startswith("Traceback") or ln.startswith('  File "'))


def case_sigint_plan(ctx, rng):
    d = ctx["tmp"] / "sigint"
    d.mkdir()
    r = run_interrupted(_PLAN_LONG + ["--json", "out.json", "--save", "traj.npz"], ctx["env"], float(rng.uniform(0.8, 2.0)),
                        signal.SIGINT, cwd=d)
    if (u := _untested(r)) is not None:
        return u
    tb = traceback_lines(r["stderr"])
    bad = tb > 0 or r["rc"] != 130 or bool(r["orphans"]) or len(r["stderr"].strip().splitlines()) != 1
    return bad, f"exit {r['rc']}, {tb} traceback lines, {len(r['stderr'].splitlines())} stderr lines, " \
                f"{len(r['orphans'])} left, exited in {r['exit_s']:.1f} s"


def case_sigterm_plan_workers(ctx, rng):
    d = ctx["tmp"] / "sigterm"
    d.mkdir()
    r = run_interrupted(_PLAN_LONG + ["--workers", "2", "--json", "out.json"], ctx["env"], float(rng.uniform(1.0, 2.0)),
                        signal.SIGTERM, cwd=d, group=False)
    if (u := _untested(r)) is not None:
        return u
    tb = traceback_lines(r["stderr"])
    bad = tb > 0 or r["rc"] != 143 or bool(r["orphans"]) or len(r["stderr"].strip().splitlines()) != 1
    return bad, f"exit {r['rc']}, {tb} traceback lines, {len(r['stderr'].splitlines())} stderr lines, " \
                f"{len(r['orphans'])} processes of its group alive 2 s later"


def _bench_interrupted(ctx, rng, sig, group, name):
    d = ctx["tmp"] / name
    d.mkdir()
    r = run_interrupted(_BENCH + ["--scene", "hard_truss", "--time-limit", "10", "--jobs", "2", "--trials", "6",
                                  "--out", "b"], ctx["env"],
                        float(rng.uniform(1.5, 3.0)), sig, cwd=d, group=group)
    if (u := _untested(r)) is not None:
        return u
    tb = traceback_lines(r["stderr"])
    bad = tb > 0 or r["rc"] != 128 + sig or bool(r["orphans"]) or len(r["stderr"].strip().splitlines()) != 1
    return bad, f"exit {r['rc']}, {tb} traceback lines, {len(r['stderr'].splitlines())} stderr lines, " \
                f"{len(r['orphans'])} left, exited in {r['exit_s']:.1f} s"


def case_sigint_bench_jobs2(ctx, rng):
    return _bench_interrupted(ctx, rng, signal.SIGINT, True, "bench-sigint")


def case_sigterm_bench_jobs2(ctx, rng):
    return _bench_interrupted(ctx, rng, signal.SIGTERM, False, "bench-sigterm")


def case_sigint_warmstart(ctx, rng):
    d = ctx["tmp"] / "warmstart-sigint"
    d.mkdir()
    r = run_interrupted(["bench", "warmstart", "--scene", "1,2", "--trials", "3", "--no-progress", "--out", "w"],
                        ctx["env"], float(rng.uniform(3.0, 7.0)), signal.SIGINT, cwd=d)
    if (u := _untested(r)) is not None:
        return u
    tb = traceback_lines(r["stderr"])
    bad = tb > 0 or r["rc"] != 130 or bool(r["orphans"]) or len(r["stderr"].strip().splitlines()) != 1
    return bad, f"exit {r['rc']}, {tb} traceback lines, {len(r['stderr'].splitlines())} stderr lines, " \
                f"{len(r['orphans'])} left, exited in {r['exit_s']:.1f} s"


def case_sigterm_plan_late(ctx, rng):
    d = ctx["tmp"] / "sigterm-late"
    d.mkdir()
    r = run_interrupted(["plan", "--scene", "2", "--workers", "2", "--json", "out.json"], ctx["env"],
                        float(rng.uniform(2.0, 4.0)), signal.SIGTERM, cwd=d, group=False)
    tb = traceback_lines(r["stderr"])
    bad = tb > 0 or r["rc"] not in (0, 1, 143) or bool(r["orphans"])
    return bad, f"exit {r['rc']}, {tb} traceback lines, {len(r['orphans'])} processes of its group alive 2 s later"


def case_fsize_save(ctx, rng):
    d = ctx["tmp"] / "fsize"
    d.mkdir()
    p = subprocess.run(_cmd(_PLAN + ["--json", "out.json", "--save", "traj.npz"]), env=ctx["env"], cwd=d,
                       capture_output=True, text=True, preexec_fn=_limit_fsize(20_000))
    js = d / "out.json"
    success_json = js.exists() and '"success": true' in js.read_text(errors="replace")
    torn = False
    if (d / "traj.npz").exists():
        try:
            with np.load(d / "traj.npz", allow_pickle=False) as z:
                _ = [z[k] for k in z.files]
        except Exception:  # noqa: BLE001 - any failure to read it back is a torn file
            torn = True
    tb = traceback_lines(p.stderr)
    bad = success_json or torn or tb > 0 or p.returncode != 2
    return bad, f"exit {p.returncode}, {tb} traceback lines, torn npz {torn}, out.json says success {success_json}"


def case_dev_full(ctx, rng):
    p = subprocess.run(_cmd(_PLAN + ["--json", "/dev/full"]), env=ctx["env"], cwd=ctx["tmp"],
                       capture_output=True, text=True)
    tb = traceback_lines(p.stderr)
    return tb > 0 or p.returncode != 2, f"exit {p.returncode}, {tb} traceback lines: " \
                                        f"{(p.stderr.strip().splitlines() or [''])[-1][:100]}"


_KERNEL = """
import casadi as ca, sys
import numpy as np
from optplan.codegen import compile_function
x = ca.SX.sym("x", 3)
f = compile_function(ca.Function("harness_sq", [x], [ca.sumsqr(x) + ca.sin(x[0])]))
r = f([1.0, 2.0, 3.0])
print(type(f).__name__, float(np.asarray(r[0] if isinstance(r, tuple) else r).ravel()[0]))
"""


def _kernel_run(ctx, cache: Path):
    env = dict(ctx["env"], OPTPLAN_CACHE=str(cache))
    return subprocess.run([sys.executable, "-c", _KERNEL], env=env, capture_output=True, text=True, timeout=120)


def _damaged_so(ctx, how: str):
    cache = ctx["tmp"] / f"cache-{how}"
    first = _kernel_run(ctx, cache)
    libs = sorted(cache.glob("harness_sq_*.so"))
    if first.returncode != 0 or not libs:
        return True, f"no kernel built ({first.stderr[-200:]})"
    lib = libs[0]
    data = lib.read_bytes()
    lib.write_bytes({"half": data[:len(data) // 2], "garbage": b"\x7fELF" + bytes(range(256)) * 16,
                     "empty": b""}[how])
    runs = [_kernel_run(ctx, cache) for _ in range(2)]
    ok = [r.returncode == 0 and "CompiledFunction" in r.stdout and traceback_lines(r.stderr) == 0 for r in runs]
    return not all(ok), "exits " + ", ".join(str(r.returncode) for r in runs) + \
        f" (first and second run after damage), tracebacks {[traceback_lines(r.stderr) for r in runs]}"


def case_half_so(ctx, rng):
    return _damaged_so(ctx, "half")


def case_garbage_so(ctx, rng):
    return _damaged_so(ctx, "garbage")


def case_empty_so(ctx, rng):
    return _damaged_so(ctx, "empty")


def case_cache_is_file(ctx, rng):
    f = ctx["tmp"] / "cache-file"
    f.write_text("not a folder")
    env = dict(ctx["env"], OPTPLAN_CACHE=str(f))
    p = subprocess.run(_cmd(_PLAN), env=env, cwd=ctx["tmp"], capture_output=True, text=True)
    tb = traceback_lines(p.stderr)
    return tb > 0 or p.returncode != 2, f"exit {p.returncode}, {tb} traceback lines"


def case_two_writers(ctx, rng):
    out = ctx["tmp"] / "bench-same"
    procs = [subprocess.Popen(_cmd(_BENCH + ["--out", str(out)]), env=ctx["env"], cwd=ctx["tmp"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    res = [p.communicate(timeout=600) for p in procs]
    lines = [json.loads(s) for s in (out / "results.jsonl").read_text().splitlines() if s.strip()]
    keys = [(r["scene"], r["trial"], r["planner"]) for r in lines]
    refused = sum(1 for p in procs if p.returncode == 2)
    summ = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    n = [d["n"] for e in summ.values() for d in e["planners"].values()]
    bad = len(keys) != len(set(keys)) or refused != 1 or any(v != 4 for v in n)
    return bad, f"{len(keys)} lines for {len(set(keys))} trials, {refused} of 2 runs refused, " \
                f"summary n {n}; exits {[p.returncode for p in procs]}; {[e.strip()[-80:] for _, e in res if e]}"


def case_foreign_lines(ctx, rng):
    out = ctx["tmp"] / "bench-foreign"
    out.mkdir()
    (out / "results.jsonl").write_text('[1, 2]\n"hello"\n{"scene": "ssps_scene1", "trial": "x", '
                                       '"planner": "tcbirrt", "seed": 0, "time_limit_s": 2.0, "clock": "cpu", '
                                       '"success": true}\n')
    p = subprocess.run(_cmd(_BENCH[:5] + ["1"] + _BENCH[6:] + ["--out", str(out)]), env=ctx["env"], cwd=ctx["tmp"],
                       capture_output=True, text=True)
    tb = traceback_lines(p.stderr)
    named = sum(1 for i in (1, 2, 3) if f"line {i}:" in p.stderr)
    return tb > 0 or p.returncode not in (0, 1) or named < 3, \
        f"exit {p.returncode}, {tb} traceback lines, {named} of 3 foreign lines reported by number"


CASES = [case_sigint_plan, case_sigterm_plan_workers, case_sigterm_plan_late, case_sigint_bench_jobs2,
         case_sigterm_bench_jobs2, case_sigint_warmstart, case_fsize_save, case_dev_full, case_half_so,
         case_garbage_so, case_empty_so, case_cache_is_file, case_two_writers, case_foreign_lines]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pythonpath", help="a source tree to put first on sys.path (e.g. an exported commit)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=1, help="run every case this many times (moments drawn anew)")
    ap.add_argument("--only", help="comma-separated case names (without case_)")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    n_bad = n_none = 0
    with tempfile.TemporaryDirectory(prefix="optplan-faults-") as tmp:
        ctx: dict[str, Any] = {"tmp": Path(tmp)}
        ctx["env"] = _env(a.pythonpath, ctx["tmp"] / "cache")
        n_run = 0
        for k in range(a.repeat):
            for case in CASES:
                name = case.__name__[5:]
                if a.only and name not in a.only.split(","):
                    continue
                ctx["tmp"] = Path(tmp) / f"r{k}"
                ctx["tmp"].mkdir(exist_ok=True)
                t0 = time.monotonic()
                bad, what = case(ctx, rng)
                if bad is None:   # nothing tested (the run ended before its signal)
                    n_none += 1
                    print(f"{name:22s} {'untested':8s} {time.monotonic() - t0:6.1f} s  {what}", flush=True)
                    continue
                n_bad += bad
                n_run += 1
                print(f"{name:22s} {'SYMPTOM' if bad else 'ok':8s} {time.monotonic() - t0:6.1f} s  {what}", flush=True)
    print(f"{n_bad} of {n_run} case runs with the symptom" + (f" ({n_none} more ended before their signal: untested)"
                                                            if n_none else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
