"""Issue 27's bar: a trivial external baseline computed outside fdi-sim from an exported dataset and
scored by ``fdi-sim bench score`` gives the same numbers as the same baseline registered as a
plugin (``examples/fdi-sim-zscore``, found through its entry point) and flown in the loop.

The plugin is installed with pip into a folder of the test session that the subprocess (and its
Dask workers) put on ``PYTHONPATH``, as ``tests/test_plugins.py`` does with the CUSUM example.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "fdi-sim-zscore"

#: flown in a subprocess that sees the plugin: the test split of one group of the suite (a case per
#: size) with zscore-v1 in the loop and full logs, exported; then the baseline computed from the
#: export alone, as a user would, and scored with ``bench score --split test``
SCRIPT = r'''
import json, sys
from pathlib import Path
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from fdi_sim.bench.run import bench_bank, fly_bench, suite_study
from fdi_sim.bench.score import score_folder
from fdi_sim.bench.suite import load_suite
from fdi_sim.cli import main
from fdi_sim.decision.persistence import k_of_n

out = Path(sys.argv[1])
suite = load_suite()
cases = suite.select(split="test", groups=("f16-airspeed-drift",))  # its test split: 0.05, 0.2, 1 kt/s from 40-90 s
assert len(cases) == 3 and {c.split for c in cases} == {"test"}
st = suite_study(suite, bench_bank(False, ["zscore-v1:signal=vc_kts"]), cases, full_logs=True)
if __name__ == "__main__":
    o = fly_bench(st, out / "run", workers=1, progress=False)
    assert o.complete, o
    assert main(["export", str(out / "run"), "--out", str(out / "data"), "--quiet"]) == 0
    # --- the external baseline: the export only, plus the baseline's own constants ------------------
    meta = json.loads((out / "data" / "suite.json").read_text())
    cases_t = pq.read_table(out / "data" / "cases.parquet").to_pylist()
    sens = pq.read_table(out / "data" / "topics" / "sensors.measurements.parquet")
    thr = {json.loads(p.read_text())["scenario"]: json.loads(p.read_text())["thresholds"]["zscore-v1"]
           for p in (out / "run" / "runs").glob("[0-9]*.json")}  # the same baseline's trained threshold
    N_STEPS, WARMUP_S, SCALE, K, N = 6, 5.0, 2.0, 3, 5  # 120 Hz log, 20 Hz detector; zscore-v1's defaults for kt; 3 of 5
    rows = {"case": [], "t_s": [], "score": [], "alarm": [], "isolation": []}
    z_all = {}
    for c in cases_t:
        m = np.asarray(sens.column("case").to_pylist()) == c["case"]
        t = np.asarray(sens.column("t_s"))[m]
        y = np.asarray(sens.column("vc_kts"))[m]
        order = np.argsort(t, kind="stable")
        t, y = t[order], y[order]
        k = np.arange(N_STEPS, t.size, N_STEPS)  # detector sample j is log row j n (fdi_sim.detectors.samples)
        tj, yj = t[k], y[k]
        s = cnt = 0.0
        for tt, v in zip(tj, yj):  # the warm-up mean, summed in order
            if tt <= WARMUP_S and np.isfinite(v):
                s += v
                cnt += 1.0
        z = np.abs((yj - s / cnt) * (1.0 / SCALE))
        h = thr[f"{c['index']:06d}.toml"]
        valid = (tj > WARMUP_S) & np.isfinite(z) & (tj >= c["arm_s"])
        exceed = valid & (z > h)
        alarm = k_of_n(exceed, K, N)
        z_all[c["case"]] = (tj, np.where(tj > WARMUP_S, z, np.nan))
        rows["case"] += [c["case"]] * tj.size
        rows["t_s"] += tj.tolist()
        rows["score"] += np.where(valid, z / h, np.nan).tolist()
        rows["alarm"] += alarm.astype(int).tolist()
        rows["isolation"] += ["vc_kts" if a and e else None for a, e in zip(alarm, exceed)]
    tbl = pa.table(rows).replace_schema_metadata({b"fdi_bench.suite_hash": meta["suite_hash"].encode()})
    pq.write_table(tbl, out / "external.parquet")
    # --- what the loop logged, for the bit-for-bit check -----------------------------------------
    st_in = pq.read_table(out / "data" / "topics" / "fdi.zscore-v1.statistic.parquet")
    dz, same_t = 0.0, True
    for case, (tj, z) in z_all.items():
        m = np.asarray(st_in.column("case").to_pylist()) == case
        t_in = np.asarray(st_in.column("t_s"))[m]
        z_in = np.asarray(st_in.column("statistic"))[m]
        keep = t_in > WARMUP_S
        same_t &= bool(np.array_equal(t_in, tj))
        if same_t:
            dz = max(dz, float(np.max(np.abs(z_in[keep] - z[keep]))))
    inloop = score_folder(st, out / "run").scored["all"]["zscore-v1"]
    print(json.dumps({"inloop": inloop, "same_t": same_t, "max_dz": dz, "export": str(out / "data"),
                      "alarms": int(sum(rows["alarm"]))}))
'''


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("zscore-site")
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                        "--target", str(target), str(EXAMPLE)], capture_output=True, text=True, timeout=600, check=False)
    assert r.returncode == 0, r.stderr
    return target


def test_the_external_baseline_scores_like_the_same_plugin_flown(site, tmp_path):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    script = tmp_path / "baseline.py"
    script.write_text(SCRIPT)
    r = subprocess.run([sys.executable, str(script), str(tmp_path)], env=env, capture_output=True, text=True,
                       timeout=1500, cwd=ROOT, check=False)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-4000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["same_t"] and got["max_dz"] == 0.0, got  # the loop's statistic, bit for bit, from the export
    assert got["alarms"] > 0 and got["inloop"]["detection"]["detected"]["k"] >= 1, got  # not an empty comparison
    s = subprocess.run([sys.executable, "-c", "import sys; from fdi_sim.cli import main; sys.exit(main(sys.argv[1:]))",
                        "bench", "score", "--scores", str(tmp_path / "external.parquet"), "--export", got["export"],
                        "--split", "test", "--json"], env=env, capture_output=True, text=True, timeout=600, cwd=ROOT,
                       check=False)
    assert s.returncode == 0, s.stderr
    ext = json.loads(s.stdout)["scores"]
    inloop = got["inloop"]
    for key in ("false_alarms", "far_per_h", "detection", "by_type", "detectability", "confusion", "alfa",
                "per_flight_detection", "event", "sample"):
        assert ext[key] == inloop[key], key
