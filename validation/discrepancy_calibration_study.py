"""The discrepancy workflow's naming rule measured: how often it names an effect on
noise-only truths (false naming), and how often it names each library effect against the
effect's size (power), on truths it does not share (issue 49).

Truths are made as in ``validation/discrepancy_truth_study.py`` (its ``truth_rve``: each
effect built through ``itr_fv``'s public API, never with the workflow's candidates; voids as
voxels of air, particles removed at random, a batch repacked at another fraction, the tester
through readings), at a larger box and a finer voxel than the workflow's tables (28 um /
0.2 um against 12 um / 0.25 um) and with packing seeds the workflow never uses:

- noise-only truths: three packings of every formulation (seeds from 700, 1700, 2700), each
  read with twelve noise seeds. The first packing's 12 tables are where the likelihood's
  noise model was checked while it was built (the base model's chi-square against its
  degrees of freedom); the other 24 are the false-naming test, seen only by this study;
- each of the seven library effects at its study size (the truth study's) and at about half
  of it (the tester, whose truth needs no solve, also at a quarter), each read with ten noise
  seeds, on the first packing.

Every table has the lab's density column (the truth RVE's sphere volumes and the handbook
densities, 0.3 % noise) and, for the tester, a thickness series; replicate noise at Table
3's spread per filler. The workflow runs at its default settings except that a named
candidate keeps the base model's correction (``correct=None``: a best-point correction is
a set of full solves per table and noise seed).

The acceptance targets were fixed before any result was seen (issue 49) and are printed with
the results:

1. false naming: an effect named in at most 5 % of the 24 noise-only test tables;
2. at least 6 of the 7 library effects named at their study size with the truth inside the
   90 % interval in at least half of the noise seeds (the power curves beside it);
3. the noise model: the base model's chi-square over its degrees of freedom on the
   noise-only tables, pooled, between 0.5 and 2.

Usage::

    python validation/discrepancy_calibration_study.py solve [--store DIR]
    python validation/discrepancy_calibration_study.py analyse [--store DIR] [--out DIR]

``solve`` makes every full solve (tables and truths; resumable: each solve is kept in the
store) and writes ``DIR/calibration_truths.json``; ``analyse`` reads them back and writes
``validation/results/discrepancy_calibration.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from itr_fv.io import write_text
from itr_identify.discrepancy import effects as library
from itr_identify.discrepancy.decision import find_discrepancy
from itr_identify.discrepancy.settings import DiscrepancySettings
from itr_identify.discrepancy.synthetic import paper_noise
from itr_identify.discrepancy.tables import build_tables, n_solves
from itr_identify.forward.fidelity import faithful_for
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements, read_measurements
from itr_surrogate.engine import SolveEngine
from itr_surrogate.requests import RVEData, SolveRequest

_spec = importlib.util.spec_from_file_location(
    "discrepancy_truth_study", Path(__file__).with_name("discrepancy_truth_study.py"))
truth = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = truth
_spec.loader.exec_module(truth)

FORMULATIONS = ("Al2O3-55", "Al2O3-58", "Al2O3-60", "Al2O3-65", "AlN-55", "AlN-58",
                "AlN-60", "AlN-62")
NULL_PACKINGS = (700, 1700, 2700)
NULL_NOISE_SEEDS = 12
#: The packing whose noise-only tables the noise model was checked on while it was built.
CHECK_PACKING = 700
EFFECT_NOISE_SEEDS = 10
#: The library effects at their study size (first) and smaller sizes (the power curve).
SIZES = {"matrix": (0.26, 0.22), "filler": (0.25, 0.5), "porosity": (0.03, 0.015),
         "fraction": (0.9, 0.95), "spots": (1e-5, 5e-6), "tester": (4e-5, 2e-5, 1e-5),
         "batch": (0.01, 0.005)}
FALSE_NAMING_TARGET = 0.05
EFFECTS_NAMED_TARGET = 6
THICKNESS_MM = (0.5, 1.0, 1.5)


#: The workflow's settings: its defaults, with the base level corrected by the ``standard``
#: faithful RVEs (24 um) rather than the shipped converged boxes (64-80 um for AlN), so that
#: the base and the 28 um truths stand for one box: a converged-box truth per effect, size
#: and noise-free table is beyond this machine (one 256^3 AlN solve takes 2-3 min).
SETTINGS = DiscrepancySettings(faithful=faithful_for("standard"))


def _size() -> "truth.Size":
    return truth.Size(FORMULATIONS, SETTINGS, truth.LIBRARY + truth.STEEPENING, 28.0, 0.2, ())


def _truth_key(case: str, value: float | None, packing: int) -> str:
    return f"{case}={value:g}@{packing}" if value is not None else f"{case}@{packing}"


def truth_solves(engine: SolveEngine, out: Path) -> dict:
    """k_iso and density of every truth RVE, per truth key and formulation."""
    path = out / "calibration_truths.json"
    done = json.loads(path.read_text()) if path.exists() else {}
    size = _size()
    jobs = [("null", None, p) for p in NULL_PACKINGS]
    jobs += [(case, v, NULL_PACKINGS[0]) for case, vals in SIZES.items() if case != "tester"
             for v in vals]
    for case, value, packing in tqdm(jobs, desc="truths", unit="truth"):
        key = _truth_key(case, value, packing)
        if key in done and len(done[key]) == len(FORMULATIONS):
            continue
        row = {}
        for i, f in enumerate(FORMULATIONS):
            saved = truth.CASES[case]
            truth.CASES[case] = (saved[0], value, saved[2])
            try:
                ms, mat = truth.truth_rve(case, fractions_of(f), size, packing + 10 * i)
            except (RuntimeError, ValueError) as exc:
                print(f"{key}: {f} left out: {exc}", flush=True)
                continue
            finally:
                truth.CASES[case] = saved
            req = SolveRequest.for_materials(RVEData.of(ms), mat, 1e-8, purpose="truth",
                                             formulation=f, effect=key)
            row[f] = {"k": float(engine.solve_one(req).k_diagonal.mean()),
                      "density": truth.sample_density(ms)}
        done[key] = row
        write_text(path, json.dumps(done, indent=1) + "\n")
    return done


def table(truths: dict, case: str, value: float | None, packing: int, seed: int
          ) -> Measurements:
    """One noisy table of a truth: four replicates (six over three thicknesses for the
    tester) per formulation, with the density column."""
    key = ("null" if case == "tester" else case)
    row = truths[_truth_key(key, None if case == "tester" else value, packing)]
    rng = np.random.default_rng(10_000 + seed)
    aux_rng = np.random.default_rng(20_000 + seed)
    values, thickness, density = {}, {}, {}
    for f, t in row.items():
        noise = paper_noise(next(iter(fractions_of(f))))
        n = 6 if case == "tester" else 4
        if case == "tester":
            th = np.resize(np.asarray(THICKNESS_MM), n) * 1e-3
            k = th / (th / t["k"] + value)
            thickness[f] = th
        else:
            k = np.full(n, t["k"])
        values[f] = k + noise * rng.standard_normal(n)
        density[f] = t["density"] * (1 + truth.DENSITY_NOISE * aux_rng.standard_normal(n))
    return Measurements(values, f"truth {case} {value} packing {packing} noise {seed}",
                        thickness or None, {"density_g_per_cm3": density})


def record(d, case: str, value: float | None, packing: int, seed: int) -> dict:
    """What one run of the workflow said, and what the calibration needs of it."""
    expected = None if case == "null" else library.by_key([case])[0].name
    w = d.winner
    interval = list(w.interval) if w is not None and w.interval is not None else None
    inside = (interval is not None and value is not None
              and interval[0] <= value <= interval[1])
    return {"case": case, "value": value, "packing": packing, "seed": seed,
            "verdict": d.verdict, "winner": w.name if w is not None else None,
            "interval_90": interval,
            "named": d.verdict == "named",
            "named_correctly": bool(d.verdict == "named" and w is not None
                                    and w.name == expected and inside),
            "chi_square": d.base.chi_square, "dof": d.base.dof(),
            "threshold": d.threshold.log_bayes_factor,
            "log_bayes_factors": {m.name: d.log_bayes_factor(m) for m in d.candidates}}


def analyse(truths: dict, tables, store_out: Path) -> list[dict]:
    rows = []
    runs = [("null", None, p, s) for p in NULL_PACKINGS for s in range(NULL_NOISE_SEEDS)]
    runs += [(case, v, NULL_PACKINGS[0], s) for case, vals in SIZES.items() for v in vals
             for s in range(EFFECT_NOISE_SEEDS)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for case, value, packing, seed in tqdm(runs, desc="workflow runs", unit="run"):
            meas = table(truths, case, value, packing, seed)
            d = find_discrepancy(meas, settings=tables.settings, tables=tables,
                                 explain=False)
            rows.append(record(d, case, value, packing, seed))
    return rows


def summarise(rows: list[dict]) -> dict:
    null = [r for r in rows if r["case"] == "null"]
    test = [r for r in null if r["packing"] != CHECK_PACKING]
    false_named = sum(r["named"] for r in test)
    chi = np.array([r["chi_square"] for r in null])
    dof = np.array([r["dof"] for r in null])
    ratio = float(chi.sum() / dof.sum())
    power = {}
    for case, vals in SIZES.items():
        power[case] = {f"{v:g}": sum(r["named_correctly"] for r in rows
                                     if r["case"] == case and r["value"] == v)
                       / EFFECT_NOISE_SEEDS for v in vals}
    named_any = {case: {f"{v:g}": sum(r["named"] for r in rows
                                      if r["case"] == case and r["value"] == v)
                        / EFFECT_NOISE_SEEDS for v in vals} for case, vals in SIZES.items()}
    at_study = sum(power[c][f"{SIZES[c][0]:g}"] >= 0.5 for c in SIZES)
    return {"null_tables": len(null), "test_tables": len(test),
            "false_named": int(false_named),
            "false_naming_rate": false_named / max(len(test), 1),
            "false_named_check_packing": int(sum(r["named"] for r in null
                                                 if r["packing"] == CHECK_PACKING)),
            "null_chi_square_mean": float(chi.mean()), "null_dof_mean": float(dof.mean()),
            "null_chi_square_over_dof": ratio,
            "threshold_median": float(np.median([r["threshold"] for r in rows])),
            "power": power, "named_any": named_any,
            "effects_named_at_study_size": int(at_study),
            "pass_false_naming": bool(false_named / max(len(test), 1) <= FALSE_NAMING_TARGET
                                      and len(test) >= 20),
            "pass_effects_named": bool(at_study >= EFFECTS_NAMED_TARGET),
            "pass_noise_model": bool(0.5 <= ratio <= 2.0)}


def write(out: Path, rows: list[dict], summary: dict, seconds: float,
          table3: dict | None) -> None:
    write_text(out / "discrepancy_calibration.json",
               json.dumps({"summary": summary, "table3": table3, "runs": rows,
                           "seconds": seconds}, indent=1) + "\n")
    s = summary

    def met(ok: bool) -> str:
        return "met" if ok else "MISSED"

    lines = ["# The discrepancy workflow's naming rule: false naming and power", "",
             f"`python validation/discrepancy_calibration_study.py analyse` ({len(rows)} "
             f"workflow runs, {seconds:.0f} s on this machine). Truths at 28 um / 0.2 um with "
             "packing seeds the workflow never uses, effects built with itr_fv's public API "
             "(validation/discrepancy_truth_study.py); the workflow at its default settings "
             "(tables at 12 um / 0.25 um, the `standard` faithful level, the naming threshold "
             "calibrated per table on 40 noise-only tables drawn from its base model), a "
             "candidate's correction the base model's; every table with a density column "
             "(0.3 % noise), the tester's with a thickness series. Targets fixed before the "
             "results were seen (issue 49).", "",
             "## Noise-only truths", "",
             f"- false-naming test ({s['test_tables']} tables: packings "
             f"{', '.join(str(p) for p in NULL_PACKINGS if p != CHECK_PACKING)} x "
             f"{NULL_NOISE_SEEDS} noise seeds): an effect named in **{s['false_named']}** "
             f"(rate {s['false_naming_rate']:.1%}; target at most "
             f"{FALSE_NAMING_TARGET:.0%}: {met(s['pass_false_naming'])})",
             f"- on the packing the noise model was checked on ({CHECK_PACKING}, "
             f"{NULL_NOISE_SEEDS} tables): named in {s['false_named_check_packing']}",
             f"- the base model's chi-square over its degrees of freedom on all "
             f"{s['null_tables']} noise-only tables, pooled: "
             f"**{s['null_chi_square_over_dof']:.2f}** (mean chi-square "
             f"{s['null_chi_square_mean']:.1f} on {s['null_dof_mean']:.0f} dof; target 0.5 - 2: "
             f"{met(s['pass_noise_model'])})",
             f"- the calibrated threshold on the log Bayes factor: median "
             f"{s['threshold_median']:.2f} over all runs", "",
             "## Power: the share of noise seeds in which the effect is named with its truth "
             "inside the 90 % interval (named at all, in brackets)", "",
             "| effect | study size | smaller | smaller |", "|---|---|---|---|"]
    for case, p in s["power"].items():
        cells = [f"{v}: {share:.0%} ({s['named_any'][case][v]:.0%})"
                 for v, share in p.items()]
        lines.append(f"| {case} | " + " | ".join(cells + ["-"] * (3 - len(cells))) + " |")
    lines += ["", f"Library effects named at their study size with the truth inside the 90 % "
              f"interval in at least half the seeds: **{s['effects_named_at_study_size']} of "
              f"{len(SIZES)}** (target at least {EFFECTS_NAMED_TARGET}: "
              f"{met(s['pass_effects_named'])}).", "",
              "## What was named on the noise-only truths", ""]
    for r in rows:
        if r["case"] == "null" and r["named"]:
            lines.append(f"- packing {r['packing']}, noise {r['seed']}: {r['winner']} "
                         f"(interval {r['interval_90']})")
    if not any(r["case"] == "null" and r["named"] for r in rows):
        lines.append("- nothing")
    lines += ["", "## Where a study-size effect was not named", ""]
    for case, vals in SIZES.items():
        misses = [r for r in rows if r["case"] == case and r["value"] == vals[0]
                  and not r["named_correctly"]]
        if misses:
            lines.append(f"- {case} = {vals[0]:g}: " + "; ".join(
                f"noise {r['seed']}: {r['verdict']}"
                + (f" ({r['winner']}, {r['interval_90']})" if r["winner"] else "")
                for r in misses))
    for name, t in (table3 or {}).items():
        rs = ", ".join(f"{k} {v:.3g}" for k, v in t["base_resistances"].items()
                       if k.startswith("R_"))
        lines += ["", f"## Table 3 (k only) under the same rule, base at the `{name}` level",
                  "", f"Base resistances {rs} m^2 K/W; base chi-square "
                  f"{t['base_chi_square']:.1f} on {t['dof']} dof; threshold "
                  f"{t['threshold']:.2f}.", "", f"**{t['verdict']}**: {t['statement']}"]
    write_text(out / "discrepancy_calibration.md", "\n".join(lines) + "\n")


def wait_for_truths(store: Path, poll_s: float = 30.0) -> dict:
    """The truths another process (``solve``) is making, once every one has landed."""
    path = store / "calibration_truths.json"
    want = len(NULL_PACKINGS) + sum(len(v) for c, v in SIZES.items() if c != "tester")
    while True:
        done = json.loads(path.read_text()) if path.exists() else {}
        if sum(len(row) == len(FORMULATIONS) for row in done.values()) >= want:
            return done
        time.sleep(poll_s)


def table3(tables, engine: SolveEngine, out: Path) -> dict:
    """Table 3 under the rule: at the study's level (``standard``) and at the default
    settings (the shipped level, the headline's, read per resistance: the same table solves
    with the shipped corrections in place of the runtime ones), the latter written as the
    workflow writes it (``discrepancy.md``, ``.json``)."""
    from itr_identify.discrepancy.best_point import corrector
    from itr_identify.discrepancy.tables import shipped_corrections
    from itr_identify.reporting.discrepancy_report import report_lines

    meas = read_measurements()
    shipped_settings = DiscrepancySettings()
    forms = {f: fractions_of(f) for f in FORMULATIONS}
    shipped = replace(tables, settings=shipped_settings, corrections={},
                      shipped=shipped_corrections(forms, shipped_settings))
    res = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, t in (("standard", tables), ("shipped", shipped)):
            t0 = time.perf_counter()
            # the default's run corrects a candidate over the threshold at its best
            # point (full solves); the study level's is read as the study reads it
            d = find_discrepancy(meas, settings=t.settings, tables=t,
                                 correct=corrector(engine) if name == "shipped" else None)
            res[name] = {"verdict": d.verdict, "statement": d.statement,
                         "base_resistances": {k: v for k, v in d.base.parameters.items()},
                         "base_chi_square": d.base.chi_square, "dof": d.base.dof(),
                         "threshold": d.threshold.log_bayes_factor,
                         "seconds": time.perf_counter() - t0}
    write_text(out / "discrepancy.json", json.dumps(d.to_dict(), indent=2) + "\n")
    lines = ["# Discrepancy between model and measurements: paper Table 3", "",
             "`python validation/discrepancy_calibration_study.py analyse`: the workflow's "
             "`find_discrepancy` on the shipped Table 3 at the default settings (issue 49: "
             "tables at 12 um / 0.25 um for the eleven candidates, the shipped level read per "
             "resistance, the naming threshold calibrated on the table, a candidate over it "
             "corrected at its best point), the report as `itr discrepancy` writes it. "
             "Table 3 has no density, mass fraction or size column: k alone.", ""]
    lines += report_lines(d, shipped_settings)
    write_text(out / "discrepancy.md", "\n".join(lines) + "\n")
    return res


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("phase", choices=("solve", "analyse"))
    p.add_argument("--store", default="discrepancy-calibration")
    p.add_argument("--out", default="validation/results")
    p.add_argument("--wait", action="store_true",
                   help="analyse: wait for the truths a running `solve` makes")
    args = p.parse_args(argv)
    store = Path(args.store)
    store.mkdir(parents=True, exist_ok=True)
    out = Path(args.out)
    t0 = time.perf_counter()
    settings = SETTINGS
    forms = {f: fractions_of(f) for f in FORMULATIONS}
    effects = library.default_effects(settings.system)
    with SolveEngine(store / "solves") as engine:
        with tqdm(total=n_solves(len(forms), settings, effects), unit="solve",
                  desc="workflow tables") as bar:
            tables = build_tables(forms, settings=settings, effects=effects, engine=engine,
                                  tick=bar.update)
        truths = (wait_for_truths(store) if args.phase == "analyse" and args.wait
                  else truth_solves(engine, store))
        if args.phase == "solve":
            print(f"solves done in {time.perf_counter() - t0:.0f} s")
            return 0
        t1 = time.perf_counter()
        rows = analyse(truths, tables, store)
        summary = summarise(rows)
        t3 = table3(tables, engine, out)
    write(out, rows, summary, time.perf_counter() - t1, t3)
    print(json.dumps({k: v for k, v in summary.items() if k != "power"}, indent=1))
    print(json.dumps(t3, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
