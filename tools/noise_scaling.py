"""How each default-bank member's statistic grows with the sensor-noise scale: the same flights
(same seeds, same turbulence) flown at noise scale 1.0 and at a higher one, each replayed through
the flight's default bank with no threshold; per member, the ratio of a high quantile of the armed
statistic. A statistic made of white sensor noise grows as the scale itself (ratio = scale); one
made of the aircraft's response to turbulence does not move (ratio 1).

    python tools/noise_scaling.py [--scale 1.3] [--seeds 201,202,203] [--duration 300]

(Development tool, issue 24: the noise cover of fdi_sim.bank.turbulence; seeds from the
``bank-development-2`` set.)
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.flightlog import read_log  # noqa: E402
from fdi_sim.scenario import from_dict, load  # noqa: E402
from fdi_sim.seeds import seeds  # noqa: E402
from fdi_sim.training import fly  # noqa: E402
from fdi_sim.training.build import bank_for_log  # noqa: E402
from fdi_sim.training.thresholds import _replay_log  # noqa: E402

CASES = (("f16_cruise_doublets", "light"), ("f16_cruise_doublets", "moderate"),
         ("dhc6_cruise_doublets", "light"), ("dhc6_cruise_doublets", "moderate"))
QUANTILE = 0.999


def statistics(name: str, level: str, scale: float, seed: int, duration_s: float, out: Path) -> dict[str, np.ndarray]:
    sc = load(ROOT / "fdi_sim" / "_scenarios" / f"{name}.toml")
    data = json.loads(sc.to_json())
    data.setdefault("atmosphere", {})["turbulence"] = level
    data.setdefault("sensors", {})["noise_scale"] = scale
    data.update(seed=seed, duration_s=duration_s, name=f"{name}_{level}_{scale:g}_{seed}")
    res = fly(from_dict(data, source=f"{name} noise {scale:g}"), out, progress=False)
    log = read_log(res.log_path)
    bank = bank_for_log(log, bank="default")
    _replay_log(bank, log, raw_thresholds=True)
    tr = bank.trace()
    armed = slice(bank.arm_samples, None)
    return {m: np.asarray(v["statistic"][armed], float)[np.asarray(v["valid"][armed], bool)] for m, v in tr.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=1.3)
    ap.add_argument("--seeds", default=",".join(map(str, seeds("bank-development-2")[:3])))
    ap.add_argument("--duration", type=float, default=300.0)
    a = ap.parse_args(argv)
    seed_list = [int(s) for s in a.seeds.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        for name, level in CASES:
            per: dict[float, dict[str, list[np.ndarray]]] = {}
            for scale in (1.0, a.scale):
                for seed in seed_list:
                    for m, x in statistics(name, level, scale, seed, a.duration, Path(tmp)).items():
                        per.setdefault(scale, {}).setdefault(m, []).append(x)
            print(f"{name} {level}: q{QUANTILE:g} of the armed statistic, noise {a.scale:g} / 1.0 (seeds {seed_list})")
            for m in per[1.0]:
                q0 = np.quantile(np.concatenate(per[1.0][m]), QUANTILE)
                q1 = np.quantile(np.concatenate(per[a.scale][m]), QUANTILE)
                print(f"  {m:28s} {q0:10.4g} {q1:10.4g}  ratio {q1 / q0:.3f}")
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
