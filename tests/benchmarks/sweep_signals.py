"""On demand (`python tests/benchmarks/sweep_signals.py SIGINT 60`, best under load: `yes > /dev/null &`):
start `fdi-sim run` of test_interrupts' 3000 s DHC-6 scenario, signal it 0.05-1.8 s after the start,
and tally the exit codes. 1 is a clean stop, -N a signal before Python ran our code; anything else
(0: a dropped stop, the run flew on) is listed. Session 10 found 1 of 60 SIGTERMs flying on.
"""
import signal, subprocess, sys, time, collections
from pathlib import Path
import numpy as np
REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "sim"))
from test_interrupts import LONG_SCENARIO

def main() -> None:
    sig = getattr(signal, sys.argv[1]); n = int(sys.argv[2])
    import tempfile
    TMP = Path(tempfile.mkdtemp())
    scn = TMP / "long.toml"; scn.write_text(LONG_SCENARIO)
    rng = np.random.default_rng(7)
    tally = collections.Counter(); bad = []
    for k in range(n):
        log = TMP / f"l{k}.mcap"
        p = subprocess.Popen([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(log), "--quiet"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
        d = float(rng.uniform(0.05, 1.8)); time.sleep(d); p.send_signal(sig)
        try:
            out, err = p.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            p.kill(); out, err = p.communicate(); tally["timeout"] += 1; bad.append((k, d, "timeout")); continue
        tally[p.returncode] += 1
        if p.returncode not in (1, -sig):
            bad.append((k, d, p.returncode, err[-300:]))
        if log.exists(): log.unlink()
    print(dict(tally)); print(bad)


if __name__ == "__main__":
    main()
