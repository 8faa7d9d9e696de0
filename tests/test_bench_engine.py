"""Benchmark engines (optplan.bench.engine): argument checks, and a real local Dask cluster giving
the same per-trial results as the in-process runner, one JSONL line per unit, resumable."""
from __future__ import annotations

import json

import pytest

from optplan import cli
from optplan.bench import warmstart as ws
from optplan.bench.engine import map_unordered, validate_engine


@pytest.mark.parametrize("engine, jobs, address, msg", [
    ("ray", 1, None, "--engine: expected one of local, dask"),
    ("local", 0, None, "--jobs: expected an integer >= 1"),
    ("local", 1, "tcp://127.0.0.1:8786", "--address: only with --engine dask"),
    ("dask", 1, " ", "--address: expected a scheduler address"),
])
def test_validate_engine(engine, jobs, address, msg):
    with pytest.raises(ValueError, match=msg):
        validate_engine(engine, jobs, address)


def test_local_engines_yield_every_unit_once():
    units = list(range(-5, 5))
    assert sorted(map_unordered(abs, units)) == sorted(abs(u) for u in units)
    assert sorted(map_unordered(abs, units, jobs=2)) == sorted(abs(u) for u in units)
    assert list(map_unordered(abs, [])) == []


@pytest.mark.parametrize("bench", ["warmstart", "tcbirrt"])
def test_cli_rejects_address_without_dask(tmp_path, capsys, bench):
    rc = cli.main(["bench", bench, "--address", "tcp://127.0.0.1:1", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and f"optplan bench {bench}: error: --address: only with --engine dask" in err
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- Dask
@pytest.fixture
def distributed():
    return pytest.importorskip("distributed")   # the optional extra 'dask'


def _strip(r: dict) -> dict:
    """A tcbirrt result line without its timings (the part that must not depend on the engine)."""
    drop = {"time_s", "cpu_time_s", "cpu_user_s", "cpu_system_s", "trial_generation_s"}
    out = {k: v for k, v in r.items() if k not in drop}
    out["stats"] = {k: v for k, v in r["stats"].items() if "time" not in k}
    return out


def test_tcbirrt_dask_local_cluster_equals_in_process(tmp_path, distributed):
    """Two worker processes of a local Dask cluster give the lines of the in-process run."""
    from distributed import LocalCluster

    from optplan.bench.tcbirrt import BenchConfig, run

    kw = dict(scenes=["1"], planners=["tcbirrt"], trials=2, first_trial=2, time_limit=10.0, seed=3, progress=False,
              plot=False)
    a = {r["trial"]: r for r in run(BenchConfig(jobs=1, out=str(tmp_path / "serial"), **kw))}
    out = tmp_path / "dask"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        cfg = BenchConfig(engine="dask", address=cluster.scheduler_address, out=str(out), **kw)
        b = {r["trial"]: r for r in run(cfg)}
        assert set(a) == set(b) == {2, 3}
        for i in a:
            assert a[i]["status"] == "exact"
            assert _strip(a[i]) == _strip(b[i])
        lines = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
        assert sorted(r["trial"] for r in lines) == [2, 3]   # one line per unit, none lost or doubled
        # killed mid-write: the truncated line is dropped and only that unit runs again
        text = (out / "results.jsonl").read_text().splitlines(keepends=True)
        (out / "results.jsonl").write_text(text[0] + text[1][:30])
        c = {r["trial"]: r for r in run(cfg)}
    lines = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert sorted(r["trial"] for r in lines) == [2, 3]
    assert all(_strip(c[i]) == _strip(a[i]) for i in a)


def test_warmstart_dask_single_writer(tmp_path, monkeypatch, distributed):
    """Warm-start units through a Dask scheduler (workers in this process, so the stand-in unit
    runner applies): every unit written exactly once, same lines as the in-process run."""
    from distributed import LocalCluster

    def fake(args):
        robot, scene, index, mode, time_limit, seed, max_wall, fixed, *rest = args
        return {"scene": scene, "trial": index, "mode": mode, "seed": seed, "time_limit_s": time_limit,
                "ipopt_max_wall_time_s": max_wall, "fixed_plane_normals": fixed, "success": index % 2 == 0,
                **({"transcription": rest[0]} if rest else {}),
                "plan_ok": True, "plan_status": "exact", "opt_status": "Solve_Succeeded", "converged": True,
                "opt_iterations": 10 + index, "opt_time_s": 0.1 * (index + 1), "opt_setup_time_s": 1.0,
                "segments": [], "error": None}

    monkeypatch.setattr(ws, "_run_unit", fake)
    kw = dict(scenes=["1", "2"], trials=4, progress=False, plot=False)
    local = ws.run(ws.WarmstartConfig(out=str(tmp_path / "local"), **kw))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        rows = ws.run(ws.WarmstartConfig(out=str(tmp_path / "dask"), engine="dask", address=cluster.scheduler_address,
                                         jobs=1, **kw))
    lines = [json.loads(x) for x in (tmp_path / "dask" / "results.jsonl").read_text().splitlines()]
    keys = [(r["scene"], r["trial"], r["mode"]) for r in lines]
    assert len(keys) == len(set(keys)) == 2 * 4 * 2
    assert rows == local


def test_dask_unreachable_address_is_a_clear_error(tmp_path, distributed):
    with pytest.raises(ConnectionError, match="no Dask scheduler answers at"):
        list(map_unordered(abs, [1, 2], engine="dask", address="tcp://127.0.0.1:9", connect_timeout=1.0))
