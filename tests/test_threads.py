"""Designs do not depend on the BLAS thread count (fdi_sim.threads).

A study's Dask workers run with ``OPENBLAS_NUM_THREADS=1``; ``fdi-sim`` in a shell gets one
OpenBLAS thread per core. Before designs were pinned to one thread, the DHC-6 linear model's
``A`` and ``C`` and the gust filter's gains differed in their last bits between the two, so a run
flown alone did not design what it designed inside its study, and a study's thresholds file did
not match the bank built in a shell (its design hash). Two real processes, one and two BLAS
threads, linearize and design the same point: the bytes must be equal.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = r"""
import hashlib, json, sys
import numpy as np
from threadpoolctl import threadpool_info
from fdi_sim.detectors.catalogue_observers import make_gust_kalman
from fdi_sim.scenario import load
from fdi_sim.training.models import model_for_scenario

sha = lambda a: hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()
sc = load(sys.argv[1])
lm = model_for_scenario(sc, 20.0)
m = lm.continuous()
det = make_gust_kalman(m, rate_hz=20.0, sim_rate_hz=float(sc.model.rate_hz))
threads = max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
print(json.dumps({"threads": threads, "A": sha(m.A), "C": sha(m.C), "gain": sha(det.design.gains[-1])}))
"""


def _design(threads: int) -> dict:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads)}
    p = subprocess.run([sys.executable, "-c", SCRIPT, str(ROOT / "scenarios" / "dhc6_cruise_doublets.toml")],
                       env=env, capture_output=True, text=True, timeout=300, check=False)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_one_and_two_blas_threads_design_the_same_bits() -> None:
    one, two = _design(1), _design(2)
    assert (one["threads"], two["threads"]) == (1, 2)  # the processes really differ in threads
    assert {k: one[k] for k in ("A", "C", "gain")} == {k: two[k] for k in ("A", "C", "gain")}


def test_a_local_cluster_leaves_the_client_environment_alone(monkeypatch) -> None:
    """Dask's nannies put ``OPENBLAS_NUM_THREADS=1`` (their pre-spawn environment) into the client's
    ``os.environ``; a subprocess started afterwards inherited it (session 10). A real local cluster
    of one worker, started and closed: the environment is as before."""
    from fdi_sim.study.execute import _client

    for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(k, raising=False)
    before = dict(os.environ)
    client, cluster = _client(1, None)
    try:
        assert client.submit(os.getenv, "OPENBLAS_NUM_THREADS").result(timeout=60) == "1"  # the worker has it
        assert dict(os.environ) == before  # the client does not
    finally:
        client.close()
        cluster.close()
