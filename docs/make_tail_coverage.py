"""Coverage of the episode-rate threshold's 95 % bound, measured at the extrapolations it is used at.

Protocol. Synthetic statistics with exactly known alarm-episode rates
(:mod:`fdi_sim.decision.tail_truth`: a Gaussian AR(1) sequence with a 10 s correlation time at
20 Hz, as the statistic ``|x|``, ``x^2`` (chi-square(1)) or a transform with a generalized-Pareto
tail of shape 0.3, under the bank's 3-of-5 persistence). Each trial draws 24 flights of 300 s
(2 h: the default bank's training) and sets the threshold with
:func:`fdi_sim.decision.tail.confident_episode_threshold` at a target rate; the threshold's true
rate comes from the exact rate curve. Coverage is the share of trials whose true rate is at or
below the target (the bound promises 95 %), with its Clopper-Pearson interval. The extrapolation
is the nominal one the issue names: (100 episodes the fit starts from / 2 h) / target. The
default banks' member targets (the bank's default ``far_per_h`` split evenly over the members of
each aircraft's default bank, :data:`MEMBER_TARGETS_PER_H`) are among the targets measured.

Cost: how much larger than the exact level a threshold is, on the ``|x|`` scale (a fault must
move the statistic that much further to be seen): the median and 95th percentile of
``u(bound) / u(true)``.

    python docs/make_tail_coverage.py [--trials 200] [--workers 2]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.bank.members import DEFAULT_BANKS, default_member_far_per_h  # noqa: E402
from fdi_sim.decision.intervals import clopper_pearson  # noqa: E402
from fdi_sim.decision.tail import MAX_EXTRAPOLATION, TAIL_EPISODES, confident_episode_threshold  # noqa: E402
from fdi_sim.decision.tail_truth import TRANSFORMS, Ar1Statistic, ar1_flights, episode_rate_curve  # noqa: E402
from fdi_sim.errors import DesignError  # noqa: E402
from fdi_sim.seeds import seeds  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402
from fdi_sim.training.flights import DEFAULT_TRAINING_FLIGHTS, DEFAULT_TRAINING_S  # noqa: E402

INPUTS = ("fdi_sim/decision/tail.py", "fdi_sim/decision/tail_truth.py", "fdi_sim/bank/members.py",
          "fdi_sim/scenario/schema.py", "fdi_sim/training/flights.py", "docs/make_tail_coverage.py")
#: the synthetic training set has the shape of the real one (fdi_sim.training.flights' defaults)
N_FLIGHTS, FLIGHT_S = DEFAULT_TRAINING_FLIGHTS, DEFAULT_TRAINING_S
TRAINING_H = N_FLIGHTS * FLIGHT_S / 3600.0
#: per aircraft: the default bank's per-member target [1/h], the default ``far_per_h`` split evenly
MEMBER_TARGETS_PER_H = default_member_far_per_h()
#: targets [1/h]: nominal extrapolations 25 x, 250 x, 2,500 x, 8,333 x (just inside MAX_EXTRAPOLATION,
#: counted from the fitted level's own rate, about 50-55 per h), then every member target not among
#: them (appended: a target's index seeds its trials, so the earlier rows keep their draws)
TARGETS_PER_H = (2.0, 0.2, 0.02, 0.006)
TARGETS_PER_H += tuple(sorted({t for t in MEMBER_TARGETS_PER_H.values() if t not in TARGETS_PER_H}, reverse=True))
SEED = seeds("tail-coverage")[0]
MD = ROOT / "docs" / "tail_coverage.md"
CARD = ROOT / "docs" / "card" / "tail_coverage.json"


#: the statistic's form given to the fit (a stream's ``tail_power``) for these statistics, at the
#: bank's extrapolations: the rows the default bank's members are judged by
GIVEN = {"gaussian |x|": (2.0, False), "chi-square(1) x^2": (1.0, True)}  # (tail_power, tail_heavy)
GIVEN_TARGETS = tuple(sorted(set(MEMBER_TARGETS_PER_H.values()) | {0.006}, reverse=True))


def _cases() -> list[tuple[str, float | None, float]]:
    """(statistic, given tail power or None, target) per row, each statistic's targets falling."""
    return ([(tr, None, tg) for tr in TRANSFORMS for tg in sorted(TARGETS_PER_H, reverse=True)]
            + [(tr, pw, tg) for tr, (pw, _) in GIVEN.items() for tg in GIVEN_TARGETS])


def _trials(args: tuple[str, float | None, float, int, int]) -> list[dict]:
    transform, power, target, first, count = args
    stat = Ar1Statistic(transform=transform)
    curve = _curve(stat)
    u_true = curve.level_at(target)
    out = []
    for t in range(first, first + count):
        rng = np.random.default_rng([SEED, list(TRANSFORMS).index(transform), TARGETS_PER_H.index(target), t])
        fl = ar1_flights(stat, N_FLIGHTS, FLIGHT_S, rng)
        try:
            heavy = True if power is None else GIVEN[transform][1]
            thr, how = confident_episode_threshold(fl, target, [FLIGHT_S / 3600.0] * N_FLIGHTS, rng, power=power,
                                                   heavy=heavy)
        except DesignError as e:
            out.append({"trial": t, "refused": str(e)})
            continue
        u = stat.level(thr)
        out.append({"trial": t, "threshold": thr, "u_ratio": u / u_true, "true_per_h": curve.rate_per_h(thr),
                    "heavy": "xi 0 (" not in how.split("of: ", 1)[1]})
    return out


_CURVES: dict[str, object] = {}


def _curve(stat: Ar1Statistic):
    if stat.transform not in _CURVES:
        _CURVES[stat.transform] = episode_rate_curve(stat, np.linspace(0.5, 7.5, 141))
    return _CURVES[stat.transform]


def measure(trials: int, workers: int) -> dict:
    jobs = [(tr, pw, tg, first, min(25, trials - first)) for tr, pw, tg in _cases() for first in range(0, trials, 25)]
    results: dict[tuple[str, float | None, float], list[dict]] = {c: [] for c in _cases()}
    t0 = time.monotonic()
    with ProcessPoolExecutor(workers) as ex:
        for i, ((tr, pw, tg, _, _), res) in enumerate(zip(jobs, ex.map(_trials, jobs))):
            results[(tr, pw, tg)] += res
            print(f"[{i + 1}/{len(jobs)}] {tr} (form {pw or 'chosen'}) at {tg} per h: {len(results[(tr, pw, tg)])} "
                  f"trials ({time.monotonic() - t0:.0f} s)", flush=True)
    rows = []
    for (tr, pw, tg), res in results.items():
        done = [r for r in res if "refused" not in r]
        n = len(done)
        k = sum(r["true_per_h"] <= tg for r in done)
        lo, hi = clopper_pearson(k, n) if n else (float("nan"), float("nan"))
        ur = np.array([r["u_ratio"] for r in done]) if done else np.array([np.nan])
        tp = np.array([r["true_per_h"] for r in done]) if done else np.array([np.nan])
        rows.append({"statistic": tr, "form": "chosen from the data" if pw is None else
                     f"given: x^{pw:g}{'' if GIVEN[tr][1] else ', light'}",
                     "target_per_h": tg, "extrapolation": TAIL_EPISODES / TRAINING_H / tg,
                     "trials": len(res), "refused": len(res) - n, "covered": int(k), "coverage": k / n if n else None,
                     "coverage_ci": [lo, hi], "heavy_share": float(np.mean([r["heavy"] for r in done])) if n else None,
                     "u_ratio_median": float(np.median(ur)), "u_ratio_p95": float(np.quantile(ur, 0.95)),
                     "true_per_h_median": float(np.median(tp)), "true_per_h_max": float(np.max(tp)),
                     "refusal": next((r["refused"] for r in res if "refused" in r), None)})
    return {"trials": trials, "n_flights": N_FLIGHTS, "flight_s": FLIGHT_S, "max_extrapolation": MAX_EXTRAPOLATION,
            "rows": rows}


def render(data: dict) -> str:
    lines = [f"Each row: {data['trials']} trials of {data['n_flights']} x {data['flight_s']:.0f} s training flights; "
             "coverage is the share whose threshold's exact rate is at or below the target (95 % promised), "
             "with its 95 % Clopper-Pearson interval. `u ratio`: the threshold's level over the exact level, "
             "on the |x| scale (median / 95th percentile): the price in detection. `tail form`: chosen from "
             "the training data, or given as a member gives it (`tail_power`, `tail_heavy`: the default bank's "
             "kinematic checks x^2 and light-tailed, its gust filter x^1; the same flights as the chosen row). "
             "`heavy`: share of trials "
             f"whose point fit chose a heavy tail. Refused: targets beyond {data['max_extrapolation']:g} x. "
             "The default banks' member targets: " + "; ".join(
                 f"{ac} {len(DEFAULT_BANKS[ac])} members, {t:.3g} per h ({TAIL_EPISODES / TRAINING_H / t:,.0f} x)"
                 for ac, t in MEMBER_TARGETS_PER_H.items()) + ".", "",
             "| statistic | tail form | target [1/h] | extrapolation | coverage [95 % CI] | refused | u ratio "
             "(median / p95) | true rate median / max [1/h] | heavy |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in data["rows"]:
        if r["coverage"] is None:
            cov = "none fitted"
        else:
            cov = f"{r['coverage']:.3f} [{r['coverage_ci'][0]:.3f}, {r['coverage_ci'][1]:.3f}]"
        lines.append(f"| {r['statistic']} | {r['form']} | {r['target_per_h']:g} | {r['extrapolation']:,.0f} x | {cov} | "
                     f"{r['refused']} of {r['trials']} | {r['u_ratio_median']:.3f} / {r['u_ratio_p95']:.3f} | "
                     f"{r['true_per_h_median']:.3g} / {r['true_per_h_max']:.3g} | "
                     f"{'' if r['heavy_share'] is None else format(r['heavy_share'], '.2f')} |")
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trials", type=int, default=200)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args()
    command = "python docs/make_tail_coverage.py" + ("" if a.trials == 200 else f" --trials {a.trials}")
    stamp = make_stamp("tail-coverage", command, INPUTS)  # the code as the numbers are made (not after)
    data = measure(a.trials, a.workers)
    data["stamp"] = stamp.__dict__ | {"inputs": list(stamp.inputs)}
    CARD.write_text(json.dumps(data, indent=1) + "\n")
    text = MD.read_text() if MD.exists() else ""
    MD.write_text(replace_block(text, stamp, render(data)))
    print(render(data))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
