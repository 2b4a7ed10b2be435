"""The naming rule on the identification's own model against truths it does not share:
false naming, power and misattribution of the eight library effects (issue 60, acceptance
1 and 2).

Truths (never the model's own construction):

- the base: the converged-box truths of the recovery study (``validation/recovery_truth.py``:
  boxes larger than the shipped corrections', packing seeds they never use, the voxel bias
  extrapolated from 0.25 and 0.2 um) at R_Al2O3 1.8e-8 and R_AlN 2.6e-8 m^2 K/W, for the
  eight single-filler formulations of Table 3;
- an effect: that truth times the effect's ratio measured on 28 um boxes at 0.2 um (packing
  seeds from 700, never the model's), each effect built through ``itr_fv``'s public API as
  the discrepancy truth study builds it (``validation/discrepancy_truth_study.py``: air voids
  resolved as spheres, particles removed at random, a batch repacked at a drawn fraction, the
  matrix and filler conductivities and solid spots through ``Materials``), at the truth's
  resistances; the film thinning as a packing with the film between particles
  (``RVESpec.min_gap_um``) of ``4 nm (0.66 - phi) / (0.66 - 0.55)``, not the model's film
  on fixed particles; the tester through readings at 0.5, 1 and 1.5 mm.

Each table: four replicates per formulation (six over three thicknesses for the tester) at
Table 3's replicate spread per filler, and the density of every sample (the truth RVE's sphere
volumes, 0.3 % noise). The model: the gap identification at the shipped level on the eight
formulations (built once; its forward models do not depend on the table), each table named
by :func:`itr_identify.discrepancy.naming.name_effect` over the eight effects.

Targets (fixed before any result, issue 60):

1. false naming: an effect named on at most 5 % of the 24 noise-only tables (noise seeds
   100 - 123, never seen while the rule was built);
2. at least 6 of the 8 effects named at their study size with the truth inside the 90 %
   interval in at least 5 of 10 noise seeds; no effect misattributed (another effect named)
   in more than 2 of 10 seeds.

Usage::

    python validation/effect_naming_study.py solve [--store DIR]
    python validation/effect_naming_study.py analyse [--store DIR] [--out DIR]

``solve`` makes the truth ratios (resumable: each solve is kept in the store and the ratios
in ``DIR/effect_truths.json``); ``analyse [--shard K/N]`` builds the model, names every
table (each table's verdict appended to ``DIR/effect_naming_runs.K.jsonl``: a killed run
resumes) and writes
``validation/results/effect_naming.json`` and ``.md``; ``report`` writes them from the tables
named so far.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


FORMULATIONS = ("Al2O3-55", "Al2O3-58", "Al2O3-60", "Al2O3-65", "AlN-55", "AlN-58",
                "AlN-60", "AlN-62")
TRUTH_R = {"R_Al2O3_silicone": 1.8e-8, "R_AlN_silicone": 2.6e-8}
#: The study size of each effect and its truth on the model's parameter.
STUDY = {"matrix": (0.26, ("ln k_silicone", math.log(0.26 / 0.18))),
         "filler": (0.25, ("ln filler_conductivity_factor", math.log(0.25))),
         "porosity": (0.03, ("void_fraction", 0.03)),
         "fraction": (0.9, ("filler_fraction_factor", 0.9)),
         "spots": (1e-5, ("G_contact_W_per_K", 1e-5)),
         "tester": (4e-5, ("R_contact_m2K_per_W", 4e-5)),
         "batch": (0.01, ("batch_fraction_sd", 0.01)),
         "film": (4.0, ("film_end_fraction", 0.66))}
FILM_END, FILM_REF = 0.66, 0.55
NULL_SEEDS = tuple(range(100, 124))
EFFECT_SEEDS = tuple(range(10))
THICKNESS_MM = (0.5, 1.0, 1.5)
TRUTH_BOX_UM, TRUTH_VOXEL_UM, TRUTH_SEED = 28.0, 0.2, 700
FALSE_NAMING_TARGET = 0.05
NAMED_TARGET = 6
MISATTRIBUTION_MAX = 2


def _truth_rve(truth, case: str, comp, seed: int):
    """The 28 um truth RVE and phase values of ``case`` (None: the base), at the truth's
    resistances."""
    from itr_fv.rve.spec import RVESpec

    spec = RVESpec(box_um=TRUTH_BOX_UM, voxel_um=TRUTH_VOXEL_UM, seed=seed)
    if case == "film":
        phi = sum(comp.values())
        film_um = 1e-3 * STUDY["film"][0] * max(0.0, (FILM_END - phi) / (FILM_END - FILM_REF))
        ms = truth.pack(comp, spec.with_(min_gap_um=film_um) if film_um > 0 else spec)
        return ms, truth.truth_materials(comp).with_values(
            resistance={(f, "silicone"): TRUTH_R[f"R_{f}_silicone"] for f in comp})
    size = truth.Size(FORMULATIONS, None, (), TRUTH_BOX_UM, TRUTH_VOXEL_UM, ())
    # the truth study's cases hold this study's sizes (matrix 0.26, filler 0.25, porosity
    # 0.03, fraction 0.9, spots 1e-5, batch 0.01)
    assert all(truth.CASES[c][1] == STUDY[c][0] for c in STUDY if c in truth.CASES)
    ms, mat = truth.truth_rve("null" if case == "base" else case, comp, size, seed)
    # the truth's resistances in place of the paper's (air voids meet the matrix through
    # none, the particles through the filler's)
    res = {(f, "silicone"): TRUTH_R[f"R_{f}_silicone"] for f in comp}
    res.update({("air", f): TRUTH_R[f"R_{f}_silicone"] for f in comp
                if "air" in mat.conductivity})
    return ms, mat.with_values(resistance=res)


def solve(store: Path) -> dict:
    """The truth ratios k_effect / k_base on the 28 um RVEs and the sample densities."""
    from itr_fv.io import write_text
    from itr_identify.inference.formulations import fractions_of
    from itr_surrogate.engine import SolveEngine
    from itr_surrogate.requests import RVEData, SolveRequest

    truth = _load("discrepancy_truth_study")
    path = store / "effect_truths.json"
    done = json.loads(path.read_text()) if path.exists() else {}
    cases = ["base"] + [c for c in STUDY if c != "tester"]
    with SolveEngine(store / "solves") as engine:
        for case in tqdm(cases, desc="truth cases", unit="case"):
            row = done.get(case, {})
            for i, f in enumerate(FORMULATIONS):
                if f in row:
                    continue
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    ms, mat = _truth_rve(truth, case, fractions_of(f), TRUTH_SEED + 10 * i)
                req = SolveRequest.for_materials(RVEData.of(ms), mat, 1e-6, purpose="truth",
                                                 formulation=f, effect=case)
                row[f] = {"k": float(engine.solve_one(req).k_diagonal.mean()),
                          "density": truth.sample_density(ms)}
                done[case] = row
                write_text(path, json.dumps(done, indent=1) + "\n")
    return done


def table(truths: dict, base_k: dict, case: str, seed: int):
    """One noisy table: four replicates (six over three thicknesses for the tester) per
    formulation, the density of each sample."""
    from itr_identify.discrepancy.synthetic import paper_noise
    from itr_identify.inference.formulations import fractions_of
    from itr_identify.inference.measurements import Measurements

    rng = np.random.default_rng(10_000 + 97 * seed + len(case))
    aux = np.random.default_rng(20_000 + 97 * seed + len(case))
    values, thick, dens = {}, {}, {}
    src = "base" if case in ("null", "tester") else case
    for f in FORMULATIONS:
        k = base_k[f] * truths[src][f]["k"] / truths["base"][f]["k"]
        n = 6 if case == "tester" else 4
        kk = np.full(n, k)
        if case == "tester":
            t = np.resize(np.asarray(THICKNESS_MM), n) * 1e-3
            kk = t / (t / k + STUDY["tester"][0])
            thick[f] = t
        values[f] = kk + paper_noise(next(iter(fractions_of(f)))) * rng.standard_normal(n)
        dens[f] = truths[src][f]["density"] * (1 + 0.003 * aux.standard_normal(n))
    return Measurements(values, f"truth {case} noise {seed}", thick or None,
                        {"density_g_per_cm3": dens})


def _model(store: Path):
    """The gap identification at the shipped level on the eight formulations (Table 3's
    values; the forward models do not depend on them) and the eight effects on it."""
    from itr_identify.discrepancy.joint_effects import JOINT_EFFECTS
    from itr_identify.discrepancy.on_identification import effects_of
    from itr_identify.inference.measurements import Measurements, read_measurements
    from itr_identify.workflows.reproduce import ReproduceSettings, _identify_all
    from itr_surrogate.engine import SolveEngine

    t3 = read_measurements()
    meas = Measurements({f: t3.values[f] for f in FORMULATIONS}, "Table 3, single fillers")
    settings = replace(ReproduceSettings(), parametrisations=("gap",))
    with SolveEngine(store / "solves") as engine:
        ident = _identify_all(meas, settings, False, print, engine)["gap"]
        effects = effects_of(ident, JOINT_EFFECTS, engine=engine)
    return ident, effects


def _runs(store: Path) -> list[dict]:
    """Every table named so far, over the shards' files."""
    rows = []
    for path in sorted(store.glob("effect_naming_runs*.jsonl")):
        rows += [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    return rows


def analyse(store: Path, out: Path, shard: tuple[int, int] = (0, 1)) -> list[dict]:
    from itr_identify.discrepancy.naming import NamingSettings, name_effect
    from itr_identify.inference.joint_fit import likelihood_of
    from itr_identify.inference.priors import ModelFormPrior

    truths = json.loads((store / "effect_truths.json").read_text())
    sr = _load("shipped_recovery_study")
    base_k = {f: v["k_truth"] for f, v in sr.truth_k().items() if f in FORMULATIONS}
    ident, effects = _model(store)
    off = ModelFormPrior(on=False)
    k, n = shard
    runs_path = store / f"effect_naming_runs.{k}.jsonl"
    done = _runs(store)
    seen = {(r["case"], r["seed"]) for r in done}
    jobs = [("null", s) for s in NULL_SEEDS] + [(c, s) for c in STUDY for s in EFFECT_SEEDS]
    # interleaved: a shard's first tables span the null and every effect
    jobs = sorted(jobs, key=lambda j: (j[1] if j[0] != "null" else j[1] - 100, j[0]))[k::n]
    for case, seed in tqdm(jobs, desc=f"tables (shard {k}/{n})", unit="table"):
        if (case, seed) in seen:
            continue
        meas = table(truths, base_k, case, seed)
        v = name_effect(lambda e, meas=meas: likelihood_of(
            ident.models, meas, ident.priors, ident.inputs["elasticity"],
            resistance=ident.resistance_prior, model_form=off, effect=e), effects,
            NamingSettings())
        row = {"case": case, "seed": seed, "verdict": v.verdict, "named": v.named,
               "tied": list(v.tied), "over": list(v.over_threshold),
               "log_bayes_factors": {c.key: v.log_bayes_factor(c.key) for c in v.candidates},
               "base_chi2": v.base.chi_square, "base_dof": v.base.dof, "base_p": v.base.p,
               "winner_value": list(v.winner.value) if v.winner and v.winner.value else None,
               "winner_resistances": ({k: list(x) for k, x in v.winner.resistances.items()}
                                      if v.winner else None)}
        with runs_path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        done.append(row)
    return _runs(store)


def realised(truths: dict) -> dict[str, float]:
    """The effect sizes the truth samples hold, read from their densities (the truth RVEs'
    sphere volumes), where they differ from the sizes asked for: a fraction loss removes
    whole particles (the mean factor over the formulations), voids are whole spheres."""
    from itr_fv.materials.paper_data import PAPER_SYSTEM
    from itr_identify.inference.formulations import fractions_of

    rho = PAPER_SYSTEM.densities()
    rm = rho["silicone"]
    frac, voids = [], []
    for f in FORMULATIONS:
        (filler, phi), = fractions_of(f).items()
        rf = rho[filler]
        frac.append((truths["fraction"][f]["density"] - rm) / (rf - rm) / phi)
        voids.append((phi * rf + (1 - phi) * rm - truths["porosity"][f]["density"]) / rm)
    return {"fraction": float(np.mean(frac)), "porosity": float(np.mean(voids))}


def summarise(rows: list[dict], truths: dict | None = None) -> dict:
    null = [r for r in rows if r["case"] == "null"]
    false_named = sum(r["verdict"] == "named" for r in null)
    held = realised(truths) if truths else {}
    per = {}
    for case, (_, (param, truth)) in STUDY.items():
        mine = [r for r in rows if r["case"] == case]
        right = sum(r["named"] == case and r["winner_value"] is not None
                    and r["winner_value"][1] <= truth <= r["winner_value"][2] for r in mine)
        t_held = held.get(case, truth)
        right_held = sum(r["named"] == case and r["winner_value"] is not None
                         and r["winner_value"][1] <= t_held <= r["winner_value"][2]
                         for r in mine)
        wrong = sum(r["verdict"] == "named" and r["named"] != case for r in mine)
        confusion = {}
        for r in mine:
            label = r["named"] if r["verdict"] == "named" else r["verdict"]
            confusion[label] = confusion.get(label, 0) + 1
        per[case] = {"seeds": len(mine), "named_right": right, "misattributed": wrong,
                     "confusion": confusion, "truth_held": t_held,
                     "named_right_held": right_held,
                     "named_any": sum(r["named"] == case for r in mine)}
    named_ok = sum(v["named_right"] >= 5 for v in per.values())
    named_ok_held = sum(v["named_right_held"] >= 5 for v in per.values())
    worst = max((v["misattributed"] for v in per.values()), default=0)
    return {"null_tables": len(null), "false_named": false_named,
            "false_naming_rate": false_named / max(len(null), 1), "per_effect": per,
            "effects_named": named_ok, "effects_named_held": named_ok_held,
            "worst_misattribution": worst,
            "pass_false_naming": len(null) >= 24
            and false_named / len(null) <= FALSE_NAMING_TARGET,
            "pass_named": named_ok >= NAMED_TARGET,
            "pass_misattribution": worst <= MISATTRIBUTION_MAX}


def write(out: Path, rows: list[dict], s: dict, seconds: float | None) -> None:
    from itr_fv.io import write_text

    write_text(out / "effect_naming.json", json.dumps({"summary": s, "runs": rows,
                                                      "seconds": seconds}, indent=1) + "\n")
    met = lambda ok: "met" if ok else "MISSED"  # noqa: E731
    lines = ["# The naming rule on the identification's own model: false naming, power, "
             "misattribution", "",
             f"`python validation/effect_naming_study.py analyse` ({len(rows)} tables"
             + (f", {seconds:.0f} s" if seconds is not None else ", written by `report` from "
                "the runs in `effect_naming_runs/`") + "). Truths: converged-box base (recovery study) times each "
             "effect's ratio on 28 um / 0.2 um boxes with other packing seeds, effects built "
             "with itr_fv's public API; the model: the gap identification at the shipped "
             "level, the eight effects as terms of its joint model. Targets fixed before the "
             "results (issue 60).", "",
             f"- false naming: {s['false_named']} of {s['null_tables']} noise-only tables "
             f"(rate {s['false_naming_rate']:.1%}; target at most "
             f"{FALSE_NAMING_TARGET:.0%}: {met(s['pass_false_naming'])})",
             f"- effects named with the truth inside the 90 % interval in at least 5 of 10 "
             f"seeds: **{s['effects_named']} of {len(STUDY)}** (target at least "
             f"{NAMED_TARGET}: {met(s['pass_named'])})",
             f"- the same against the sizes the truth samples hold (read from their "
             f"densities: fraction factor {s['per_effect']['fraction']['truth_held']:.4f} "
             f"where 0.9 was asked, particles being removed whole; void fraction "
             f"{s['per_effect']['porosity']['truth_held']:.4f}): "
             f"**{s['effects_named_held']} of {len(STUDY)}** (the target was fixed on the "
             "sizes asked for; this line says what the misses there are)",
             f"- the most seeds in which one effect was taken for another: "
             f"{s['worst_misattribution']} (target at most {MISATTRIBUTION_MAX}: "
             f"{met(s['pass_misattribution'])})", "",
             "## Confusion matrix (truth in rows; what the rule said, over 10 noise seeds)", ""]
    labels = list(STUDY) + ["tie", "unexplained", "none"]
    lines += ["| truth | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
    for case, v in s["per_effect"].items():
        lines.append(f"| {case} ({STUDY[case][0]:g}) | " + " | ".join(
            str(v["confusion"].get(lab, 0)) for lab in labels) + " |")
    lines += ["", "## Per effect: named with the truth inside the 90 % interval (of the seeds "
              "run)", "", "| effect | truth (asked) | inside | truth (held) | inside | named "
              "at all |", "|---|---|---|---|---|---|"]
    for case, v in s["per_effect"].items():
        lines.append(f"| {case} | {STUDY[case][1][1]:.4g} | {v['named_right']} of "
                     f"{v['seeds']} | {v['truth_held']:.4g} | {v['named_right_held']} of "
                     f"{v['seeds']} | {v['named_any']} |")
    null = [r for r in rows if r["case"] == "null"]
    lines += ["", "## Noise-only tables", "",
              f"Base model's chi-square over its dof, pooled: "
              f"{sum(r['base_chi2'] for r in null) / max(sum(r['base_dof'] for r in null), 1):.2f}"
              f" on {len(null)} tables; the largest log Bayes factor on each: "
              + ", ".join(f"{max(r['log_bayes_factors'].values()):.1f}" for r in null) + "."]
    write_text(out / "effect_naming.md", "\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("phase", choices=("solve", "analyse", "report"))
    p.add_argument("--store", default="effect-naming-study")
    p.add_argument("--out", default="validation/results")
    p.add_argument("--shard", default="0/1", help="analyse: this process's share K/N of the "
                   "tables (run N processes, K = 0 .. N-1; the last one's summary holds all "
                   "that finished)")
    args = p.parse_args(argv)
    k, _, n = args.shard.partition("/")
    shard = (int(k), int(n or 1))
    if not 0 <= shard[0] < shard[1]:
        raise SystemExit(f"--shard: expected K/N with 0 <= K < N, got {args.shard!r}")
    store, out = Path(args.store), Path(args.out)
    store.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.phase == "solve":
        solve(store)
        print(f"truth solves done in {time.perf_counter() - t0:.0f} s")
        return 0
    rows = _runs(store) if args.phase == "report" else analyse(store, out, shard)
    s = summarise(rows, json.loads((store / "effect_truths.json").read_text()))
    write(out, rows, s, None if args.phase == "report" else time.perf_counter() - t0)
    print(json.dumps({k: v for k, v in s.items() if k != "per_effect"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
