"""A study against a real Dask cluster on localhost: `dask scheduler` and two `dask worker` processes.

Issue 14's bars: kill a worker process during a study and it completes with every run exactly
once; interrupt the whole study and start it again: finished runs are not flown again, and the
final results equal an uninterrupted study's.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fdi_sim.study.execute import TIMING_KEYS, done_runs, fly_study, load_records
from fdi_sim.study.spec import load_study

BIN = Path(sys.executable).parent
STUDY = """
kind = "study"
name = "t_cluster"
scenario = "dhc6_cruise_doublets"
seed = 3
runs = 30
duration_s = 30.0
[sample]
"initial.h_ft" = { uniform = [5500.0, 6500.0] }
"atmosphere.turbulence" = { choice = ["light", "moderate"] }
[bank]
bank = "default"
calibration_flights = 4
calibration_duration_s = 60.0
design = { point = "grid", turbulence = "moderate" }
"""


def _results(recs: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_KEYS} for r in recs]


class Cluster:
    """`dask scheduler` and `dask worker` processes, each in its own process group."""

    def __init__(self, tmp: Path, env: dict[str, str]) -> None:
        self.tmp, self.env = tmp, env
        self.sched_file = tmp / "scheduler.json"
        self.scheduler = subprocess.Popen([str(BIN / "dask"), "scheduler", "--scheduler-file", str(self.sched_file),
                                           "--port", "0", "--no-dashboard"], env=env, start_new_session=True,
                                          stdout=subprocess.DEVNULL, stderr=open(tmp / "scheduler.log", "w"))
        t0 = time.monotonic()
        while not self.sched_file.is_file():
            assert time.monotonic() - t0 < 60, (tmp / "scheduler.log").read_text()
            time.sleep(0.2)
        time.sleep(0.3)
        self.address = json.loads(self.sched_file.read_text())["address"]
        self.workers: list[subprocess.Popen] = []

    def add_worker(self) -> subprocess.Popen:
        w = subprocess.Popen([str(BIN / "dask"), "worker", self.address, "--nthreads", "1", "--nworkers", "1",
                              "--no-dashboard"], env=self.env, start_new_session=True, stdout=subprocess.DEVNULL,
                             stderr=open(self.tmp / f"worker{len(self.workers)}.log", "w"))
        self.workers.append(w)
        return w

    def wait_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout="10s") as c:
            c.wait_for_workers(n, timeout=60)

    def kill(self, p: subprocess.Popen) -> None:
        os.killpg(p.pid, signal.SIGKILL)  # the nanny and its worker process: a machine gone
        p.wait(timeout=30)

    def close(self) -> None:
        for p in [*self.workers, self.scheduler]:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in [*self.workers, self.scheduler]:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory):
    tmp = tmp_path_factory.mktemp("cluster")
    env = {**os.environ, "FDI_SIM_CACHE": str(tmp / "cache"), "PYTHONUNBUFFERED": "1"}
    study = tmp / "study.toml"
    study.write_text(STUDY)
    mp = pytest.MonkeyPatch()
    mp.setenv("FDI_SIM_CACHE", env["FDI_SIM_CACHE"])
    # the reference: the same study uninterrupted, on a local cluster (it also fills the design cache)
    ref = tmp / "ref"
    o = fly_study(load_study(study), ref, workers=2, progress=False)
    assert o.complete
    cl = Cluster(tmp, env)
    cl.add_worker()
    cl.add_worker()
    cl.wait_workers(2)
    yield tmp, study, cl, _results(load_records(ref))
    cl.close()
    mp.undo()


def _start(study: Path, out: Path, address: str, env_tmp: Path) -> subprocess.Popen:
    env = {**os.environ, "FDI_SIM_CACHE": str(env_tmp / "cache")}
    return subprocess.Popen([str(BIN / "fdi-sim"), "study", str(study), "--out", str(out), "--scheduler", address,
                             "--quiet", "--no-report"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _wait_runs(out: Path, n: int, p: subprocess.Popen, timeout_s: float = 240.0) -> None:
    t0 = time.monotonic()
    while len(done_runs(out)) < n:
        assert p.poll() is None, p.communicate()
        assert time.monotonic() - t0 < timeout_s
        time.sleep(0.05)


def test_interrupted_study_resumes_without_flying_twice(setup) -> None:
    tmp, study, cl, ref = setup
    out = tmp / "interrupted"
    p = _start(study, out, cl.address, tmp)
    _wait_runs(out, 8, p)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 1, err
    k = len(done_runs(out))
    assert 8 <= k < 30, err
    assert "run the same command" in err
    before = {i: (out / "runs" / f"{i:06d}.json").stat().st_mtime_ns for i in done_runs(out)}
    p = _start(study, out, cl.address, tmp)
    so, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    m = re.search(r"this call  flew (\d+) runs", so)
    assert m and int(m.group(1)) == 30 - k, so  # the finished runs were not flown again
    assert {i: (out / "runs" / f"{i:06d}.json").stat().st_mtime_ns for i in before} == before
    assert _results(load_records(out)) == ref


def test_killed_worker_study_completes_with_every_run_once(setup) -> None:
    tmp, study, cl, ref = setup
    out = tmp / "killed"
    p = _start(study, out, cl.address, tmp)
    _wait_runs(out, 6, p)
    cl.kill(cl.workers[0])
    so, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    recs = load_records(out)
    assert [r["index"] for r in recs] == list(range(30))
    assert len(list((out / "runs").glob("*.json"))) == 30
    assert _results(recs) == ref
    # the scheduler saw the worker go (and moved its runs): the study did not just finish first
    log = (tmp / "scheduler.log").read_text()
    assert "Remove worker" in log and len(done_runs(out)) == 30
