"""``optplan plan`` ends its process without the interpreter's shutdown once its report and files are
written (``optplan.cli._end_plan_process``): what it printed and wrote is complete, its exit status is the
run's, and no segment worker outlives it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest
from fault_harness import group_members


@pytest.mark.parametrize("early", [True, False], ids=["early-worker", "late-worker"])
def test_plan_command_ends_with_its_output_complete_and_no_worker_left(tmp_path, early):
    env = dict(os.environ, OPTPLAN_BACKGROUND_COMPILE="0")
    env.pop("PYTHONUNBUFFERED", None)   # stdout to a pipe is block-buffered: the end must flush it
    out, traj = tmp_path / "out.json", tmp_path / "traj.npz"
    # the command line's own process (optplan.cli.main with no argv), its segment worker forked before
    # planning (as when the load average leaves a core free) or after it
    code = ("import sys; import optplan.pipeline_workers as W; "
            f"W._a_core_is_free = lambda: {early}; "
            "from optplan.cli import main; sys.argv[0] = 'optplan'; sys.exit(main())")
    p = subprocess.Popen([sys.executable, "-c", code, "plan", "--scene", "1", "--workers", "2",
                          "--json", str(out), "--save", str(traj)], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, start_new_session=True, text=True)
    stdout, stderr = p.communicate(timeout=300)
    time.sleep(0.5)
    left = group_members(p.pid)
    assert left == [], f"processes of the command left: {left}"
    rec = json.loads(out.read_text())
    assert p.returncode == (0 if rec["success"] else 1), stderr
    assert rec["success"] and rec["files"] == [str(traj)] and rec["n_segments"] == 4
    assert rec["opt_iterations"] > 0 and len(rec["attempts"]) == rec["n_segments"]
    with np.load(traj) as z:
        assert z["q"].shape == (len(z["t"]), 14) and bool(z["constrained"][-1])
    # the whole report reached the pipe: one line per segment, the last one included
    seg_lines = [ln for ln in stdout.splitlines() if ln.strip().startswith("segment ")]
    assert len(seg_lines) == rec["n_segments"], stdout
    assert "Traceback" not in stderr, stderr
