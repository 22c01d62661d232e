"""docs/bench.md's generated blocks: the suite (``bench-suite``), the leaderboard (``leaderboard``,
also as the page ``docs/leaderboard.html``) and what the benchmark costs on this machine (``bench-cost``).

The leaderboard flies (or reuses) each bank on its selection of the newest suite
(:data:`fdi_sim.bench.suite.LATEST`) with ``fdi-sim bench run``'s code, into
``--out-root/<digest>/<bank>``: ``<digest>`` is the digest of the code the flights depend on
(:data:`FLIGHT`), so a changed detector never reuses an old folder, and the same code resumes an
interrupted regeneration without flying a case twice.

    python docs/make_bench_tables.py --out-root DIR [--workers 2] [--suite-only]

Banks and selections (:data:`BANKS`): the two default banks (one per aircraft, the ``default`` bank
flies each case's own) and every registered detector side by side, each on the whole suite, with the
selection in the table's caption. Both are ranked per aircraft: a default bank is one bank per
aircraft, and a method's rate on one aircraft says nothing about the other.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.stamp import generated_block, inputs_digest, make_stamp, replace_block
from fdi_sim.units import S_PER_H

MD = ROOT / "docs" / "bench.md"
#: the leaderboard as a page of its own (issue 27: Markdown and HTML, shipped in docs/)
HTML = ROOT / "docs" / "leaderboard.html"
COMMAND = "python docs/make_bench_tables.py --out-root DIR --workers 2"
SUITE_INPUTS = ("fdi_sim/_bench", "fdi_sim/bench/suite.py", "docs/make_bench_tables.py")
CODE = ("aircraft", "scenarios", "fdi_sim/_bench", "fdi_sim/bench", "fdi_sim/decision", "fdi_sim/bank",
        "fdi_sim/detectors", "fdi_sim/training", "fdi_sim/sensors", "fdi_sim/faults", "fdi_sim/sim", "fdi_sim/pilot",
        "fdi_sim/linear", "fdi_sim/scenario", "fdi_sim/study/execute.py", "fdi_sim/study/spec.py",
        "fdi_sim/scoring.py", "docs/make_bench_tables.py")
#: what the flights depend on (the folders are keyed by its digest): CODE without the scoring, the rendering
#: and the study executor (whose records are checked by tests/study and tests/bench: resume, 1 worker = 2)
FLIGHT = tuple(x for x in CODE if x not in ("fdi_sim/bench", "fdi_sim/decision", "fdi_sim/study/execute.py",
                                            "fdi_sim/study/spec.py", "fdi_sim/scoring.py",
                                            "docs/make_bench_tables.py")) + (
    "fdi_sim/bench/run.py", "fdi_sim/bench/suite.py") + tuple(
    f"fdi_sim/decision/{p.name}" for p in sorted((ROOT / "fdi_sim" / "decision").glob("*.py")))
#: (bank name, selection keywords of Suite.select, what the caption says)
BANKS: tuple[tuple[str, dict, str], ...] = (
    ("default", {}, "the whole suite"),
    ("every-detector", {},
     ("the whole suite (every registered detector side by side, thresholds trained at the same design points, "
      "reconfiguration off; a member that cannot be designed on an aircraft is left out there)")),
)


def _suite_table() -> str:
    from fdi_sim.bench.suite import SPLITS, load_suite

    s = load_suite()
    lines = [f"`{s.name}`, hash `{s.hash}`: {len(s.cases)} cases, {s.flight_h():.1f} planned flight hours.", "",
             "| group | aircraft | phases | cases | flight h | " + " | ".join(SPLITS) + " | fault (sizes) or label |",
             "|---|---|---|---|---|---|---|---|---|"]
    for g in s.model.groups:
        cs = [c for c in s.cases if c.group == g.name]
        f = g.fault or {}
        tgt = f.get("target")
        tgt = ", ".join(tgt["choice"]) if isinstance(tgt, dict) and "choice" in tgt else tgt
        what = (f"{f['type']} on {tgt}" + (f" ({g.size.key} {', '.join(f'{v:g}' for v in g.size.values)})"
                                           if g.size else "")) if f else (f"hard negative: {g.negative}" if g.negative
                                                                          else "fault-free")
        lines.append(f"| {g.name} | {cs[0].aircraft} | {len(g.phases)} | {len(cs)} | {s.flight_h(tuple(cs)):.1f} | "
                     + " | ".join(str(sum(c.split == x for c in cs)) for x in SPLITS) + f" | {what} |")
    return "\n".join(lines)


def _fly(out_root: Path, workers: int, banks: tuple[str, ...]) -> dict[str, dict]:
    from fdi_sim import registry
    from fdi_sim.bank.members import DEFAULT_BANKS
    from fdi_sim.bench.cli import read_calls, record_call
    from fdi_sim.bench.run import bench_bank, fly_bench, suite_study
    from fdi_sim.bench.score import score_folder
    from fdi_sim.bench.suite import load_suite

    suite = load_suite()
    digest = inputs_digest(FLIGHT)[:12]
    out: dict[str, dict] = {}
    for name, sel, caption in BANKS:
        if name not in banks:
            continue
        bank = bench_bank(True) if name == "default" else bench_bank(False, registry.ids("detector"))
        cases = suite.select(**sel)
        st = suite_study(suite, bank, cases)
        folder = out_root / digest / name
        print(f"{name}: {len(cases)} cases, {suite.flight_h(cases):.1f} flight h -> {folder}", flush=True)
        t0 = time.perf_counter()
        o = fly_bench(st, folder, workers=workers, progress=True)
        record_call(folder, o, workers, None)
        if o.interrupted or not o.complete:
            raise SystemExit(f"{name}: {o.done_before + o.flown} of {o.total} cases flown; run again to go on")
        res = score_folder(st, folder)
        recs = [json.loads(p.read_text()) for p in sorted((folder / "runs").glob("[0-9]*.json"))]
        recs = [r for r in recs if r["index"] in set(st.selected)]
        out[name] = {"result": res.to_dict(), "caption": caption, "folder": str(folder),
                     "wall_s_sum": sum(float(r.get("wall_s", 0.0)) for r in recs),
                     "flight_h": sum(float(r.get("flight_h", 0.0)) for r in recs),
                     "this_call": {"flown": o.flown, "wall_s": time.perf_counter() - t0, "flight_h": o.flight_h},
                     "calls": read_calls(folder), "design_far_per_h": float(bank.fdi["far_per_h"]),
                     "members": (f"those designed at each point, of the {len(bank.detectors)} registered" if bank.detectors
                                 else "/".join(sorted({str(len(v)) for v in DEFAULT_BANKS.values()})) + " per aircraft")}
    return out


def _leaderboard_parts(flown: dict[str, dict]) -> list[tuple[str, str, str, list]]:
    """The leaderboard as ``(title, caption, heading, rows)`` per table (title and caption on a bank's
    first table only): the default banks in one table (their rows name the aircraft's bank); every
    detector in one table per aircraft, under a line saying which (sixteen methods twice would bury
    the comparison). Markdown and HTML render the same parts."""
    from fdi_sim.bench.leaderboard import AIRCRAFT_LABELS, rank, result_rows

    parts = []
    for name, d in flown.items():
        r = d["result"]
        subsets = [k for k in r["scored"] if k.startswith("aircraft:")]
        if name == "default":
            tables = [("", rank([row for sub in subsets for row in result_rows(r, sub)]))]
        else:
            tables = [(f"{AIRCRAFT_LABELS[sub]}: {r['scored'][sub]['bank']['cases']} cases, "
                       f"{r['scored'][sub]['bank']['exposure_h']:.1f} h of exposure outside the fault windows.",
                       rank(result_rows(r, sub))) for sub in subsets]
        nc, dep = r["not_scored"], r["departed"]
        title = "Default banks" if name == "default" else "Every registered detector"
        caption = (f"{d['caption']}; "
                   f"design rate {d['design_far_per_h']:g} false alarms per flight hour per bank, split over its "
                   f"members ({d['members']}): "
                   f"{r['cases']} cases, {r['flight_h']:.1f} flight h scored; {len(dep)} departed (scored up to the "
                   f"departure: {_departures(dep)})"
                   + (f"; {len(nc)} not scored ({', '.join(sorted({x['status'] for x in nc}))}: "
                      f"{', '.join(x['case'] for x in nc[:4])}{'...' if len(nc) > 4 else ''})" if nc else "") + ".")
        for i, (heading, rows) in enumerate(tables):
            parts.append((title, caption, heading, rows) if i == 0 else ("", "", heading, rows))
    return parts


def _alfa_note() -> str:
    from fdi_sim.bench.leaderboard import ALFA_RLS

    return (f"ALFA's RLS (Keipour et al. 2019): precision {ALFA_RLS['precision']:.2%}, recall "
            f"{ALFA_RLS['recall']:.2%}, mean detection time {ALFA_RLS['mean_detection_time_s']:g} s. \"beats\": "
            "both the precision and the recall above it on the ALFA criterion here, in brackets the fault classes "
            "where that holds (each class's fault flights with every fault-free one).")


def _leaderboard(flown: dict[str, dict]) -> str:
    from fdi_sim.bench.leaderboard import leaderboard_markdown

    out = []
    for title, caption, heading, rows in _leaderboard_parts(flown):
        if title:
            out += [f"**{title}**, {caption}", ""]
        out += ([heading, ""] if heading else []) + [leaderboard_markdown(rows), ""]
    return "\n".join(out + [_alfa_note()])


def _leaderboard_html(flown: dict[str, dict], suite: str) -> str:
    """The same tables as :func:`_leaderboard`, for ``docs/leaderboard.html``."""
    import html

    from fdi_sim.bench.leaderboard import leaderboard_table_html

    out = [f"<p>{html.escape(suite)}; the tables and how each metric is computed: docs/bench.md.</p>"]
    for title, caption, heading, rows in _leaderboard_parts(flown):
        if title:
            out.append(f"<h2>{html.escape(title)}</h2><p>{html.escape(caption)}</p>")
        if heading:
            out.append(f"<h3>{html.escape(heading)}</h3>")
        out.append(leaderboard_table_html(rows))
    out.append(f"<p>{html.escape(_alfa_note())}</p>")
    return "\n".join(out)


def _by_group(flown: dict[str, dict]) -> str:
    """The default banks per suite group: where the false alarms and the detections are."""
    from fdi_sim.bench.leaderboard import far_cell

    r = flown["default"]["result"]
    lines = [f"Design rate {flown['default']['design_far_per_h']:g} false alarms per flight hour per bank.", "",
             ("| group | aircraft | cases | exposure h | false alarms | per h [95 %] | faults detected [95 %] | "
              "delay median [s] | isolation right |"), "|---|---|---|---|---|---|---|---|---|"]
    for key, methods in r["scored"].items():
        if not key.startswith("group:") or "bank" not in methods:
            continue
        s = methods["bank"]
        ac = key.split(":", 1)[1].split("-")[0]
        far = far_cell(s)
        d = s["detection"]
        det = "-" if not d["faults"] else f"{d['detected']['k']}/{d['faults']} [{d['detected']['ci'][0]:.2f}, " \
                                          f"{d['detected']['ci'][1]:.2f}]"
        iso = "-" if not d["isolation"]["n"] else f"{d['isolation']['k']}/{d['isolation']['n']}"
        med = "-" if d["delay_s_median"] is None else f"{d['delay_s_median']:.2f}"
        lines.append(f"| {key.split(':', 1)[1]} | {ac} | {s['cases']} | {s['exposure_h']:.2f} | {s['false_alarms']} | "
                     f"{far} | {det} | {med} | {iso} |")
    lines += ["", "The fault-free flights (hard negatives included) per phase:", "",
              "| phase | flights | exposure h | false alarms | per h [95 %] | flights with one |", "|---|---|---|---|---|---|"]
    for key, methods in r["scored"].items():
        if key.startswith("phase:") and "bank" in methods:
            s = methods["bank"]
            far = far_cell(s)
            a = s["alfa"]
            lines.append(f"| {key.split(':', 1)[1]} | {s['cases']} | {s['exposure_h']:.2f} | {s['false_alarms']} | {far} | "
                         f"{a['fp']} |")
    lines += ["", ("Every case of each aircraft (fault cases outside their fault windows included) by the turbulence it "
                   "flew in, which the bank is not told, and by how the flight ended (a departed flight is scored up to "
                   "its departure):"), "",
              "| aircraft | air or ending | cases | exposure h | false alarms | per h [95 %] |", "|---|---|---|---|---|---|"]
    for key, methods in r["scored"].items():
        if key.startswith(("air:", "ended:")) and "bank" in methods:
            s = methods["bank"]
            _, ac, what = key.split(":")
            far = far_cell(s)
            lines.append(f"| {ac} | {what} | {s['cases']} | {s['exposure_h']:.2f} | {s['false_alarms']} | {far} |")
    return "\n".join(lines)


def _departures(dep: list[dict]) -> str:
    from collections import Counter

    groups = Counter(d["case"].split("/")[0] for d in dep)
    return ", ".join(f"{g} {n}" for g, n in groups.most_common()) or "none"


def _cost(flown: dict[str, dict], workers: int) -> str:
    lines = [("| bank | cases | flight h | summed run wall time [s] | flight h per worker-hour (runs only) | "
              "calls that flew: cases, flight h, wall [s] (designs included), flight h per hour (designs) |"),
             "|---|---|---|---|---|---|"]
    for name, d in flown.items():
        rate = d["flight_h"] / (d["wall_s_sum"] / S_PER_H) if d["wall_s_sum"] > 0 else None
        calls = "; ".join(f"{c['flown']}, {c['flight_h']:.1f}, {c['wall_s']:.0f}, "
                          f"{c['flight_h'] / (c['wall_s'] / S_PER_H):.0f} ({c['workers'] or 'all'} workers"
                          f"{', interrupted' if c['interrupted'] else ''}; {_designs(c)})" for c in d["calls"])
        lines.append(f"| {name} | {d['result']['cases']} | {d['flight_h']:.1f} | {d['wall_s_sum']:.0f} | "
                     f"{'-' if rate is None else f'{rate:.0f}'} | {calls or 'not recorded (flown before the calls log)'} |")
    lines += ["", ("On this machine (2 cores). The summed run wall time leaves out the designs (the training flights "
                   "and calibrations of each design point, cached and counted in no run); a call's wall time includes "
                   "them. A call's designs: how many it needed and their wall time summed over the workers (seconds "
                   "when the cache held them all, minutes each that flew its training flights).")]
    return "\n".join(lines)


def _designs(call: dict) -> str:
    """A call's designs as a cell: ``68 designs, 1,850 s`` (``designs not recorded`` for a call logged before
    :func:`fdi_sim.bench.cli.record_call` wrote them)."""
    if "designs" not in call:
        return "designs not recorded"
    return f"{call['designs']} designs, {call['design_wall_s']:,.0f} s"


def main(argv: list[str] | None = None) -> int:
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("--out-root", type=Path, default=None, help="where the benchmark folders are kept (reused)")
    a.add_argument("--workers", type=int, default=2)
    a.add_argument("--suite-only", action="store_true", help="only the suite table (flies nothing)")
    a.add_argument("--banks", default=",".join(b for b, _, _ in BANKS),
                   help=f"the banks to fly and rank (default: all of {', '.join(b for b, _, _ in BANKS)})")
    args = a.parse_args(argv)
    text = MD.read_text()
    text = replace_block(text, make_stamp("bench-suite", "python docs/make_bench_tables.py --suite-only", SUITE_INPUTS),
                         _suite_table())
    if not args.suite_only:
        if args.out_root is None:
            raise SystemExit("give --out-root DIR (the benchmark folders, reused when the code is the same)")
        banks = tuple(b.strip() for b in args.banks.split(",") if b.strip())
        unknown = sorted(set(banks) - {b for b, _, _ in BANKS})
        if unknown:
            raise SystemExit(f"unknown bank(s) {unknown}; give some of {', '.join(b for b, _, _ in BANKS)}")
        flown = _fly(args.out_root, args.workers, banks)
        command = COMMAND + ("" if args.banks == a.get_default("banks") else f" --banks {','.join(banks)}")
        text = replace_block(text, make_stamp("leaderboard", command, CODE), _leaderboard(flown))
        if set(flown) == {b for b, _, _ in BANKS}:  # the page holds every bank's tables, or is not rewritten
            from fdi_sim.bench.leaderboard import html_page
            from fdi_sim.bench.suite import FROZEN, LATEST

            su = (LATEST, FROZEN[LATEST])  # what _fly flew (load_suite() checked the hash)
            HTML.write_text(html_page(generated_block(make_stamp("leaderboard-html", command, CODE),
                                                      _leaderboard_html(flown, f"{su[0]}, hash {su[1][:16]}..."))))
            print(f"wrote {HTML}")
        if "default" in flown:
            text = replace_block(text, make_stamp("bench-by-group", command, CODE), _by_group(flown))
        text = replace_block(text, make_stamp("bench-cost", command, CODE), _cost(flown, args.workers))
    MD.write_text(text)
    print(f"wrote {MD}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
