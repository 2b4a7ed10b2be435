"""The discrepancy workflow against truths it does not share (issues 25 and 40).

Each truth table is read twice: with the auxiliary columns a lab would have (the Archimedes
density of every sample, from the truth RVE's own phase volumes and the handbook phase
densities, 0.3 % noise; a thickness series where the effect is the tester's) and as a
k-only table (one thickness). With the columns, the study scores whether the effect is
named with its truth inside the 90 % interval (the null case and effects outside the
library: nothing named); k-only, whether the tied set holds the truth and the measurement
the workflow names to decide it separates the truth from the rest of that set.

Every measurement table is made with the full solver on RVEs of a larger box and a finer
voxel than the workflow's tables, packed with seeds the workflow never uses, and every effect
is built through ``itr_fv``'s public API, never with ``itr_identify.discrepancy.effects``:

- matrix and filler conductivity: ``Materials.with_values``;
- porosity: air spheres of 0.8 um placed among the particles (random sequential addition) and
  voxelized with ``Microstructure.from_spheres`` (the workflow's candidate homogenises voids
  smaller than a voxel into the matrix: another model of the same physics);
- filler fraction below nominal: particles removed at random, ``Microstructure.from_spheres``;
- solid contact spots: ``Materials.with_values(contact_conductance=...)``;
- the tester's contact resistance: ``k_app = t / (t / k + R_c)`` at three thicknesses;
- a batch effect: each formulation packed at its nominal fraction plus a random offset;
- outside the library: silicone films between touching particles (the packing's
  ``min_gap_um``) and agglomeration (a packing at ``phi / 0.94`` emptied around the box
  centre back to ``phi``: a resin pocket and crowded filler around it).

Replicate noise at Table 3's spread per filler; the resistances at the paper's values.

Sizes: ``ci`` (the default test run: five formulations, three candidates, tables at 12 um /
0.5 um, truth at 14 um / 0.25 um, the workflow's faithful correction at 14 um from 0.28 and
0.5 um) and ``full`` (Table 3's single-filler formulations, the whole library, the workflow's
default settings: tables at 12 um / 0.25 um, correction from two 24 um packings at 0.2 and
0.25 um; truth at 28 um / 0.2 um).

Usage::

    python validation/discrepancy_truth_study.py [--size ci|full] [--out DIR]
        [--store DIR] [--workers N]

Writes ``DIR/discrepancy_truth.json`` and ``.md`` (``full``: ``validation/results/``). Every
full solve is kept in the store (default ``DIR/solves``): a killed run resumes.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from itr_fv import Materials, Microstructure
from itr_fv.io import write_text
from itr_fv.materials.paper_data import PAPER_SYSTEM, paper_parameters
from itr_fv.rve import FillerSpec, build_rve
from itr_fv.rve.spec import RVESpec
from itr_identify.discrepancy import effects as library
from itr_identify.discrepancy.best_point import corrector
from itr_identify.discrepancy.decision import find_discrepancy
from itr_identify.discrepancy.settings import DiscrepancySettings
from itr_identify.discrepancy.synthetic import paper_noise
from itr_identify.discrepancy.tables import build_tables, n_solves
from itr_identify.forward.fidelity import FaithfulRVE, faithful_for
from itr_identify.forward.model import ForwardSettings
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements, read_measurements
from itr_surrogate.engine import SolveEngine
from itr_surrogate.requests import RVEData, SolveRequest

MATRIX = "silicone"
THICKNESS_MM = (0.5, 1.0, 1.5)
TRUTH_SEED = 700
AIR_K = 0.026


@dataclass(frozen=True)
class Size:
    formulations: tuple[str, ...]
    settings: DiscrepancySettings
    effects: tuple[str, ...]             # the workflow's candidates (keys)
    truth_box_um: float
    truth_voxel_um: float
    cases: tuple[str, ...]


LIBRARY = ("matrix", "filler", "porosity", "fraction", "spots", "tester", "batch")
STEEPENING = ("film", "agglomeration", "basis", "shell")

SIZES = {
    "ci": Size(("Al2O3-45", "Al2O3-55", "Al2O3-60", "AlN-50", "AlN-60"),
               DiscrepancySettings(
                   forward=ForwardSettings(RVESpec(box_um=12.0, voxel_um=0.5, seed=3),
                                           replicas=2),
                   faithful=FaithfulRVE((("Al2O3", 14.0), ("AlN", 14.0)), 0.28, 0.5)),
               ("matrix", "porosity", "fraction", "tester"), 14.0, 0.25,
               ("null", "porosity", "tester")),
    "full": Size(("Al2O3-55", "Al2O3-58", "Al2O3-60", "Al2O3-65", "AlN-55", "AlN-58",
                  "AlN-60", "AlN-62"), DiscrepancySettings(faithful=faithful_for("standard")),
                 LIBRARY + STEEPENING, 28.0, 0.2,
                 ("null",) + LIBRARY + ("agglomeration", "films", "width")),
}

#: Each case: (effect key of the library that should be named or None, true value, and
#: whether the table has thicknesses). Outside the library: ``films`` (a uniform 50 nm
#: silicone film at every contact, five times the film candidate's physical range, and
#: not thinning with the fraction) and ``width`` (a size distribution 1.3 times wider in
#: ln D than Table 1's).
CASES = {
    "null": (None, None, False),
    "matrix": ("matrix", 0.26, False),
    "filler": ("filler", 0.25, False),
    "porosity": ("porosity", 0.03, False),
    "fraction": ("fraction", 0.9, False),
    "spots": ("spots", 1e-5, False),
    "tester": ("tester", 4e-5, True),
    "batch": ("batch", 0.01, False),
    "films": (None, 0.05, False),
    "agglomeration": ("agglomeration", 0.94, False),
    "width": (None, 1.3, False),
}


def truth_materials(comp: dict[str, float]) -> Materials:
    """Paper conductivities and resistances, gap contact model (public API only)."""
    r = paper_parameters()
    k = PAPER_SYSTEM.conductivities(comp)
    return Materials(k, {(f, MATRIX): r[f"R_{f}_{MATRIX}"] for f in comp}, matrix=MATRIX,
                     contact="gap")


def pack(comp: dict[str, float], spec: RVESpec, width: float = 1.0) -> Microstructure:
    fillers = [FillerSpec.from_table1(f, v) for f, v in comp.items()]
    if width != 1.0:
        fillers = [replace(x, sigma=x.sigma * width) for x in fillers]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return build_rve(spec, fillers, 0, matrix=MATRIX).microstructure


def remove_particles(ms: Microstructure, keep: np.ndarray) -> Microstructure:
    t = ms.particles
    return Microstructure.from_spheres(t.centers_m[keep], t.radii_m[keep],
                                       list(np.asarray(t.material)[keep]), ms.box_m,
                                       ms.shape, matrix=MATRIX, contact=t.contact)


def with_voids(ms: Microstructure, fraction: float, seed: int, radius_um: float = 0.4
               ) -> Microstructure:
    """Air spheres of ``radius_um`` among the particles up to ``fraction`` of the box."""
    t = ms.particles
    box = ms.box_m
    r = radius_um * 1e-6
    n = int(round(fraction * np.prod(box) / (4 / 3 * math.pi * r ** 3)))
    rng = np.random.default_rng(seed)
    placed = np.empty((n, 3))
    m = 0
    for x in rng.uniform(0, 1, size=(600_000, 3)) * box:
        d = t.centers_m - x
        d -= box * np.round(d / box)
        if np.any(np.einsum("ij,ij->i", d, d) < (t.radii_m + 1.05 * r) ** 2):
            continue
        e = placed[:m] - x
        e -= box * np.round(e / box)
        if np.any(np.einsum("ij,ij->i", e, e) < (2.1 * r) ** 2):
            continue
        placed[m] = x
        m += 1
        if m == n:
            break
    if m < n:
        raise RuntimeError(f"voids: room for {m} of {n}")
    c = np.vstack([t.centers_m, placed])
    radii = np.concatenate([t.radii_m, np.full(n, r)])
    return Microstructure.from_spheres(c, radii, list(t.material) + ["air"] * n, box,
                                       ms.shape, matrix=MATRIX, contact=t.contact)


def truth_rve(case: str, comp: dict[str, float], size: Size, seed: int
              ) -> tuple[Microstructure, Materials]:
    """The RVE and phase values of one formulation under the case's true effect."""
    spec = RVESpec(box_um=size.truth_box_um, voxel_um=size.truth_voxel_um, seed=seed)
    mat = truth_materials(comp)
    key, value, _ = CASES[case]
    if case == "films":
        return pack(comp, spec.with_(min_gap_um=value)), mat
    if case == "width":
        return pack(comp, spec, width=value), mat
    if case == "agglomeration":
        ((filler, phi),) = comp.items()
        crowded = pack({filler: phi / value}, spec)
        t = crowded.particles
        d = t.centers_m - crowded.box_m / 2
        order = np.argsort(np.einsum("ij,ij->i", d, d))          # nearest the centre first
        vol = t.radii_m ** 3
        drop = order[np.cumsum(vol[order]) <= (1 - value) * vol.sum()]
        keep = np.ones(len(vol), dtype=bool)
        keep[drop] = False
        return remove_particles(crowded, keep), mat
    if key == "batch":
        ((filler, phi),) = comp.items()
        offset = value * np.random.default_rng(seed + 1).standard_normal()
        try:
            return pack({filler: phi + offset}, spec), mat
        except (RuntimeError, ValueError):     # beyond the packer's reach: the other side
            return pack({filler: phi - offset}, spec), mat
    ms = pack(comp, spec)
    if key == "matrix":
        mat = mat.with_values(conductivity={MATRIX: value})
    elif key == "filler":
        mat = mat.with_values(conductivity={f: value * k for f, k in mat.conductivity.items()
                                            if f != MATRIX})
    elif key == "spots":
        mat = mat.with_values(contact_conductance={(f, f): value for f in comp})
    elif key == "fraction":
        vol = ms.particles.radii_m ** 3
        order = np.random.default_rng(seed).permutation(len(vol))
        keep = np.ones(len(vol), dtype=bool)
        keep[order[np.cumsum(vol[order]) <= (1 - value) * vol.sum()]] = False
        ms = remove_particles(ms, keep)
    elif key == "porosity":
        ms = with_voids(ms, value, seed)
        k = {**mat.conductivity, "air": AIR_K}
        res = {**mat.resistance, ("air", MATRIX): 0.0}
        for f in comp:
            res[("air", f)] = mat.resistance_between(f, MATRIX)
        mat = Materials(k, res, MATRIX, contact="gap")
    return ms, mat


#: Relative noise of one Archimedes density (a lab's balance and wetting).
DENSITY_NOISE = 0.003


def sample_density(ms: Microstructure) -> float:
    """The density of the truth RVE from its spheres' volumes (particles and air voids,
    voids massless; the rest matrix), g/cm^3: the sample's, not its voxel image's."""
    rho = {**PAPER_SYSTEM.densities(), "air": 0.0}
    t = ms.particles
    vol = 4.0 / 3.0 * math.pi * t.radii_m ** 3 / float(np.prod(ms.box_m))
    mats = np.asarray(t.material)
    share = {m: float(vol[mats == m].sum()) for m in set(mats)}
    return float(sum(v * rho[m] for m, v in share.items())
                 + (1.0 - sum(share.values())) * rho[MATRIX])


def truth_table(case: str, size: Size, engine: SolveEngine, seed: int
                ) -> tuple[Measurements, Measurements]:
    """The case's table with the lab's auxiliary columns and the same truth k-only."""
    key, value, thick = CASES[case]
    rng = np.random.default_rng(seed)
    aux_rng = np.random.default_rng(seed + 1000)      # k's noise as in issue 25's tables
    values, thickness, density, k_only = {}, {}, {}, {}
    for i, f in enumerate(size.formulations):
        comp = fractions_of(f)
        try:
            ms, mat = truth_rve(case, comp, size, TRUTH_SEED + 10 * i)
        except (RuntimeError, ValueError) as exc:   # a packing beyond reach (films, crowding)
            print(f"{case}: {f} left out of the table: {exc}", flush=True)
            continue
        req = SolveRequest.for_materials(RVEData.of(ms), mat, 1e-8, purpose="truth",
                                         formulation=f, effect=case)
        k = float(engine.solve_one(req).k_diagonal.mean())
        noise = paper_noise(next(iter(comp)))
        n = 6 if thick else 4
        t = np.resize(np.asarray(THICKNESS_MM), n) * 1e-3 if thick else None
        k_app = t / (t / k + value) if key == "tester" else np.full(n, k)
        values[f] = k_app + noise * rng.standard_normal(n)
        if t is not None:
            thickness[f] = t
        density[f] = sample_density(ms) * (1 + DENSITY_NOISE * aux_rng.standard_normal(n))
        k1 = (1e-3 / (1e-3 / k + value)) if key == "tester" else k
        k_only[f] = k1 + noise * aux_rng.standard_normal(4)
    return (Measurements(values, f"truth: {case} (density)", thickness or None,
                         {"density_g_per_cm3": density}),
            Measurements(k_only, f"truth: {case} (k only)"))


def _expected_name(case: str) -> str | None:
    key = CASES[case][0]
    return None if key is None else library.by_key([key])[0].name


def score(case: str, d, columns: str) -> dict:
    """One table's outcome: with the auxiliary columns, named (with the truth inside the
    interval) or silent; k-only, the tied set and the measurement named to decide it."""
    key, value, _ = CASES[case]
    expected = _expected_name(case)
    winner = d.winner.name if d.winner is not None else None
    interval = list(d.winner.interval) if d.winner is not None and d.winner.interval else None
    if case == "null":
        ok = d.verdict == "none"
    elif expected is None:
        ok = d.verdict != "named"                 # outside the library: not named
    else:
        ok = (d.verdict == "named" and winner == expected and interval is not None
              and interval[0] <= value <= interval[1])
    after = d.winner or (d.candidates[0] if d.candidates else d.base)
    tied = [m.name for m in d.tied]
    truth_model = "base" if case == "null" else expected
    named = [x for x in d.deciding if x.key in d.deciding_keys]
    in_tied = truth_model in tied if truth_model is not None else None
    decides = None
    if named and truth_model is not None:
        # the truth told from every other tied model by one of the measurements named
        others = [m for m in tied if m != truth_model]
        decides = all(any(x.separation.get((a, b), x.separation.get((b, a), -1.0))
                          >= x.margin for x in named
                          for a, b in [(truth_model, o)]) for o in others)
    return {"case": case, "columns": columns,
            "truth": (f"{expected or case} = {value:g}" if value is not None
                      else "noise only"),
            "verdict": d.verdict, "winner": winner, "interval_90": interval,
            "chi2_dof_before": d.chi_square_per_dof(d.base),
            "chi2_dof_after": d.chi_square_per_dof(after), "after": after.name,
            "base_resistances": {k: v for k, v in d.base.parameters.items()},
            "named_correctly": bool(ok), "tied": tied, "truth_in_tied": in_tied,
            "deciding": " + ".join(d.deciding_keys) or None,
            "deciding_separates_truth": decides,
            "ranking": [{"key": x.key, "pairs_separated": x.separated,
                         "pairs": len(x.separation),
                         "separation": [[a, b, v] for (a, b), v in x.separation.items()]}
                        for x in d.deciding],
            "corrected_at_best": d.corrected_at_best,
            "statement": d.statement,
            "intervals": [{"model": m.name, "best": m.parameters[e.parameter],
                           "interval_90": list(m.interval)}
                          for m in d.candidates for e in d.effects
                          if e.name == m.name and m.interval is not None]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", choices=sorted(SIZES), default="ci")
    p.add_argument("--out", default=None)
    p.add_argument("--store", default=None)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--cases", default=None, help="comma-separated subset of the cases")
    args = p.parse_args(argv)
    size = SIZES[args.size]
    cases = tuple(args.cases.split(",")) if args.cases else size.cases
    out = Path(args.out or ("validation/results" if args.size == "full"
                            else "discrepancy-truth-ci"))
    out.mkdir(parents=True, exist_ok=True)
    store = Path(args.store) if args.store else out / "solves"
    t0 = time.perf_counter()
    rows = []
    forms = {f: fractions_of(f) for f in size.formulations}
    effects = library.by_key(size.effects)
    with SolveEngine(store, workers=args.workers) as engine:
        with tqdm(total=n_solves(len(forms), size.settings, effects), unit="solve",
                  desc="workflow tables") as bar:
            tables = build_tables(forms, settings=size.settings, effects=effects,
                                  engine=engine, tick=bar.update)
        for j, case in enumerate(tqdm(cases, desc="truth tables", unit="case")):
            with_columns, k_only = truth_table(case, size, engine, seed=40 + j)
            for meas, columns in ((with_columns, "density" + (", thickness series"
                                                               if CASES[case][2] else "")),
                                  (k_only, "k only")):
                tables.effect_corrections.clear()
                d = find_discrepancy(meas, settings=size.settings, tables=tables,
                                     correct=corrector(engine))
                rows.append(score(case, d, columns))
                r = rows[-1]
                print(f"{case} [{columns}]: {d.verdict} ({r['winner']}); tied "
                      f"{r['tied']}; deciding {r['deciding']}", flush=True)
                write_results(out, args.size, size, rows, time.perf_counter() - t0)
        if args.size == "full" and not args.cases:
            tables.effect_corrections.clear()
            table3 = find_discrepancy(read_measurements(), settings=size.settings,
                                      tables=tables, correct=corrector(engine))
            write_table3(out, table3)
    print(f"wrote {out / 'discrepancy_truth.md'}")
    return 0


def write_table3(out: Path, d) -> None:
    """Table 3 under the faithful base: the verdict, the model-form term and the
    leave-one-formulation-out coverage."""
    write_text(out / "discrepancy_truth_table3.json", json.dumps(d.to_dict(), indent=2) + "\n")


def write_results(out: Path, name: str, size: Size, rows: list[dict], seconds: float
                  ) -> None:
    """The JSON and markdown of the cases done so far (atomic: a killed run leaves the
    last complete pair)."""
    fw = size.settings.forward
    fr = size.settings.faithful
    summary = {"size": name, "done": f"{len(rows)} of {len(size.cases)} cases",
               "formulations": list(size.formulations),
               "workflow": {"box_um": fw.box_um, "voxel_um": fw.voxel_um,
                            "replicas": fw.replicas, "seed": fw.seed,
                            "faithful": fr.to_dict() if fr else None,
                            "effects": list(size.effects)},
               "truth": {"box_um": size.truth_box_um, "voxel_um": size.truth_voxel_um,
                         "seeds_from": TRUTH_SEED},
               "cases": rows, "seconds": seconds}
    write_text(out / "discrepancy_truth.json", json.dumps(summary, indent=2) + "\n")
    lines = ["# The discrepancy workflow against truths it does not share", "",
             f"`python validation/discrepancy_truth_study.py --size {name}` "
             f"({len(rows)} tables, {seconds:.0f} s on this machine). "
             f"Workflow tables at {fw.box_um:g} um / "
             f"{fw.voxel_um:g} um ({fw.replicas} replicas, seed {fw.seed})"
             + (f", faithful correction from {fr.packings} packings of "
                f"{', '.join(f'{k} {v:g} um' for k, v in fr.boxes_um)} at {fr.voxel_um:g} "
                f"and {fr.coarse_voxel_um:g} um, a named candidate's at its best point"
                if fr else "")
             + f"; candidates {', '.join(size.effects)}; truth at {size.truth_box_um:g} um "
             f"/ {size.truth_voxel_um:g} um, packing seeds from {TRUTH_SEED}, effects built "
             "with itr_fv's public API, the density of each sample from the truth RVE's "
             f"sphere volumes and the handbook densities ({DENSITY_NOISE:.1%} noise); "
             "formulations " + ", ".join(size.formulations) + ".", "",
             "## With the auxiliary columns", "",
             "| case | truth | columns | verdict | named (90 % interval) | chi-square/dof "
             "before -> after | correct |", "|---|---|---|---|---|---|---|"]
    aux = [r for r in rows if r["columns"] != "k only"]
    for r in aux:
        iv = (f" ({r['interval_90'][0]:.3g} - {r['interval_90'][1]:.3g})"
              if r["interval_90"] else "")
        lines.append(f"| {r['case']} | {r['truth']} | {r['columns']} | {r['verdict']} | "
                     f"{r['winner'] or '-'}{iv} | {r['chi2_dof_before']:.2f} -> "
                     f"{r['chi2_dof_after']:.2f} ({r['after']}) | "
                     f"{'yes' if r['named_correctly'] else 'no'} |")
    lib = [r for r in aux if CASES[r["case"]][0] in LIBRARY]
    lines += ["", f"Library effects named with the truth inside the 90 % interval: "
              f"{sum(r['named_correctly'] for r in lib)} of {len(lib)}.", "",
              "## The same truths as k-only tables", "",
              "| case | truth | verdict | tied set | truth in it | measurement named | it "
              "separates the truth | ranking (pairs separated) |",
              "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["columns"] != "k only":
            continue
        rank = ", ".join(f"{x['key']} {x['pairs_separated']}/{x['pairs']}"
                         for x in r["ranking"])
        lines.append(f"| {r['case']} | {r['truth']} | {r['verdict']} | "
                     f"{'; '.join(r['tied']) or '-'} | {_yn(r['truth_in_tied'])} | "
                     f"{r['deciding'] or '-'} | {_yn(r['deciding_separates_truth'])} | "
                     f"{rank or '-'} |")
    lines += ["", "Statements:", ""] + [f"- {r['case']} [{r['columns']}]: {r['statement']}"
                                        for r in rows]
    write_text(out / "discrepancy_truth.md", "\n".join(lines) + "\n")


def _yn(x) -> str:
    return "-" if x is None else ("yes" if x else "no")


if __name__ == "__main__":
    sys.exit(main())
