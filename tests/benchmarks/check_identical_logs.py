"""Bit-identity check: fly every scenario in ``scenarios/`` and fingerprint its log.

Run on demand (not collected by the test suite: it flies all 14 scenarios, a few minutes)::

    python tests/benchmarks/check_identical_logs.py --write /tmp/ref_hashes.json      # reference
    python tests/benchmarks/check_identical_logs.py --compare /tmp/ref_hashes.json    # after a change

For each log it records the SHA-256 of the file and, per topic, the SHA-256 of the decoded
content (vector topics: the field names, the data array's bytes and the log times; event topics:
the times and the JSON payloads). A change to the hot path must leave both unchanged; the topic
hashes are the ones that matter (the file also carries the package versions in its metadata, so
its hash changes with a version bump while the flown numbers do not). Exit status 1 on any
difference, naming the scenario and the topic.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fdi_sim import scenario
from fdi_sim.flightlog import read_log
try:
    from fdi_sim.training import fly
except ImportError:  # a tree from before fdi_sim.training (its loop designed its own bank)
    from fdi_sim.sim import run as fly

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _topic_digest(topic) -> str:
    h = hashlib.sha256()
    if hasattr(topic, "data"):  # vector topic: the exact bytes, NaN payloads included
        h.update(json.dumps(list(topic.fields)).encode())
        h.update(np.ascontiguousarray(topic.data).tobytes())
        h.update(np.ascontiguousarray(topic.log_time_ns).tobytes())
    elif hasattr(topic, "events"):
        for e in topic.events:
            h.update(np.float64(e.t_s).tobytes())
            h.update(json.dumps(e.payload, sort_keys=True).encode())
    else:  # a raw topic: its repr is all we know of it
        h.update(repr(topic).encode())
    return h.hexdigest()


def fingerprint(path: Path) -> dict:
    """File SHA-256 and per-topic content SHA-256 of one log."""
    log = read_log(path)
    return {
        "file_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "topics": {name: _topic_digest(t) for name, t in sorted(log.topics.items())},
    }


def fly_all(pattern: str = "*.toml") -> dict[str, dict]:
    """Fly every scenario matching ``pattern``; fingerprint each log."""
    out = {}
    with tempfile.TemporaryDirectory() as d:
        for path in sorted(SCENARIOS.glob(pattern)):
            t0 = time.perf_counter()
            sc = scenario.load(path)
            res = fly(sc, d, progress=False)
            out[path.name] = {"status": res.status, "steps": res.summary.steps, **fingerprint(res.log_path)}
            print(f"{path.name:34} {res.status:10} {res.summary.steps:6d} steps  {time.perf_counter() - t0:6.1f} s",
                  flush=True)
    return out


def compare(ref: dict, new: dict) -> list[str]:
    """Differences between two fingerprint sets (empty: identical topics)."""
    bad = []
    for name in sorted(set(ref) | set(new)):
        if name not in new:
            bad.append(f"{name}: in the reference, not flown now")
            continue
        if name not in ref:  # a scenario added since the reference: nothing to compare it with
            continue
        a, b = ref[name], new[name]
        if (a["status"], a["steps"]) != (b["status"], b["steps"]):
            bad.append(f"{name}: status/steps {a['status']}/{a['steps']} -> {b['status']}/{b['steps']}")
        for topic in sorted(set(a["topics"]) | set(b["topics"])):
            if a["topics"].get(topic) != b["topics"].get(topic):
                bad.append(f"{name}: topic {topic} differs")
    return bad


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", type=Path, help="write the fingerprints to this JSON file")
    ap.add_argument("--compare", type=Path, help="compare against this JSON file")
    ap.add_argument("--pattern", default="*.toml", help="scenario file glob (default: all)")
    args = ap.parse_args(argv)
    new = fly_all(args.pattern)
    if args.write:
        args.write.write_text(json.dumps(new, indent=1, sort_keys=True))
    if args.compare:
        ref = json.loads(args.compare.read_text())
        if args.pattern != "*.toml":
            ref = {k: v for k, v in ref.items() if k in new}
        bad = compare(ref, new)
        both = [n for n in new if n in ref]
        same_files = sum(ref[n]["file_sha256"] == new[n]["file_sha256"] for n in both)
        print(f"{len(both)} scenarios in the reference: {len(both) - len({b.split(':')[0] for b in bad})} with "
              f"identical topics, {same_files} with identical files")
        extra = sorted(set(new) - set(ref))
        if extra:
            print(f"not in the reference (not compared): {', '.join(extra)}")
        for b in bad:
            print("DIFFERENT", b)
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
