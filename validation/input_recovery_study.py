"""Recovery against truths that do not share the model (issue 47, point 6 and acceptance 2).

The default identification (``itr identify --parametrisation gap`` at the ``shipped`` level,
the conductivities marginalised with their default priors) is run on synthetic measurements
made from truths it never shares, each over ten noise seeds. A truth is
covered by a seed where the 90 % (marginal) interval holds it; a seed *fails* where the truth is
outside and the value is flagged ``determined`` (a value flagged ``model misfit``,
``bounded`` or ``undetermined`` tells the reader not to take it as determined).

Truths (k_iso of each formulation, W/(m K); every one solved in a box larger than the
corrections', on packing seeds neither they nor the cheap replicas use, at 0.25 and 0.2 um
on the same particles with the voxel bias extrapolated by the gap model's order):

- ``old contacts``: issue 39's converged-box truth (``validation/recovery_truth.py``:
  R_Al2O3_silicone 1.8e-8, R_AlN_silicone 2.6e-8; Al2O3 at 40 um, AlN at 80 um; the eight
  single-filler formulations), solved before the stated-film contacts: touching particles
  there meet at the packer's clearance, a size-dependent film of about 1e-3 (r_i + r_j)
  (median 3.2 nm for Al2O3-60, 5.8 nm for AlN-60), where the model's contacts have none.
- ``all k +8 %``: the same truth with every conductivity 8 % above nominal, exactly
  (k(1.08 k_m, 1.08 k_f, R / 1.08) = 1.08 k(k_m, k_f, R) holds for the discrete model): the
  measurements are 1.08 times the first truth's, the true resistances 1.8e-8 / 1.08 and
  2.6e-8 / 1.08.
- ``k_m +8 %``, ``3 nm film``, ``volume basis`` and ``nominal (stated film)``: the Al2O3
  formulations at 40 um (packing 801), with the matrix conductivity alone 8 % above nominal,
  touching particles at a 3 nm film, Table 1 read as volume-weighted lognormals, and the
  nominal inputs (``validation/input_truths.py``); R_Al2O3_silicone 1.8e-8. Only
  R_Al2O3_silicone is identified from these (the AlN formulations were not solved at a
  converged box on 2 cores).

Measurements: four replicates per formulation with Table 3's replicate noise (the
root-mean-square replicate standard deviation of the formulation's filler system).
Each (truth, seed) is written to ``validation/results/input_recovery_runs/`` as it finishes
(a killed run redoes only the unfinished ones). Writes
``validation/results/input_recovery.md`` and ``input_recovery.json``.

Usage::

    python validation/input_recovery_study.py [--seeds 10] [--truth NAME ...]
    python validation/input_recovery_study.py --report-only
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "validation"))
RESULTS = ROOT / "validation" / "results"
RUNS = RESULTS / "input_recovery_joint_runs"
OUT = RESULTS / "input_recovery_joint.md"
OUT_JSON = RESULTS / "input_recovery_joint.json"
#: Issue 59's acceptance 2, fixed before the run: covered (at least 8 of 10 seeds, no miss
#: flagged determined) and the geometric mean of best / truth within these.
BEST_RANGE = (0.8, 1.25)
REPLICATES = 4
SCALE = 1.08


def _extrapolated(rows_by_voxel: dict[float, dict[str, float]]) -> dict[str, float]:
    """k_iso per formulation with the voxel bias removed (Richardson, the gap model's order)."""
    from input_truths import VOXELS_UM

    from itr_identify.forward.fidelity import BIAS_ORDER, richardson

    coarse, fine = VOXELS_UM
    out = {}
    for f in sorted(set(rows_by_voxel.get(coarse, {})) & set(rows_by_voxel.get(fine, {}))):
        out[f] = float(richardson(np.array([rows_by_voxel[fine][f]]),
                                  np.array([rows_by_voxel[coarse][f]]), coarse / fine,
                                  BIAS_ORDER)[0])
    return out


def truths() -> dict[str, dict]:
    """Per truth: ``k`` (formulation -> k_iso, W/(m K)), ``R`` (true resistances) and a
    description; a truth whose solves have not finished is left out."""
    import input_truths as it
    from recovery_truth import TRUTH as OLD_TRUTH
    from shipped_recovery_study import truth_k

    from itr_fv.materials.formulation_names import fractions_of
    from itr_identify.forward.corrections_table import campaign_rows

    out: dict[str, dict] = {}
    old = {f: t["k_truth"] for f, t in truth_k().items() if len(fractions_of(f)) == 1}
    if len(old) == 8:
        out["old contacts"] = {"k": old, "R": dict(OLD_TRUTH),
                               "what": "issue 39's converged-box truth, contacts at the "
                                       "packer's clearance (a film of ~1e-3 (r_i + r_j))"}
        out["all k +8 %"] = {"k": {f: SCALE * k for f, k in old.items()},
                             "R": {n: v / SCALE for n, v in OLD_TRUTH.items()},
                             "what": "the same, every conductivity +8 % (exact scaling)"}
    names = {"km+8": "k_m +8 %", "film3": "3 nm film", "volume": "volume basis",
             "nominal": "nominal (stated film)"}
    for key, (_, what) in it.TRUTHS.items():
        by_voxel: dict[float, dict[str, float]] = {}
        for v in it.VOXELS_UM:
            folder = it.folder(key, v)
            if folder.exists():
                by_voxel[v] = {r["formulation"]: r["k_iso"] for r in campaign_rows(folder)}
        k = _extrapolated(by_voxel)
        if len(k) == len(it.FORMULATIONS):
            out[names[key]] = {"k": k, "R": dict(it.TRUTH), "what": what,
                               "k_voxels": {str(v): d for v, d in by_voxel.items()}}
    return out


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name).strip("_")


def run(n_seeds: int, which: list[str] | None) -> None:
    from shipped_recovery_study import _write, noise_sd

    from itr_fv.materials.formulation_names import fractions_of
    from itr_identify.inference.measurements import Measurements
    from itr_identify.inference.pipeline import identify
    from itr_identify.reporting.headline import parameter_flag
    from itr_identify.workflows.reproduce import ReproduceSettings

    RUNS.mkdir(parents=True, exist_ok=True)
    settings = ReproduceSettings()
    sds = noise_sd()
    models: dict = {}
    for name, truth in truths().items():
        if which and name not in which:
            continue
        _write(RUNS / f"{_slug(name)}__truth.json", truth)
        for seed in range(n_seeds):
            out = RUNS / f"{_slug(name)}__seed{seed}.json"
            if out.exists():
                continue
            rng = np.random.default_rng(seed)
            values = {f: k + sds["+".join(sorted(fractions_of(f)))]
                      * rng.standard_normal(REPLICATES) for f, k in truth["k"].items()}
            meas = Measurements(values, f"synthetic, truth {name!r} (noise seed {seed})")
            t = time.perf_counter()
            ident = identify(meas, "gap", settings=settings.forward,
                             grid_points=settings.grid_points, seed=seed, reuse=models,
                             echo=lambda line: None, floor_check=False)
            models.update(ident.models)
            row = {"truth": name, "seed": seed, "seconds": time.perf_counter() - t,
                   "fit": {k: ident.fit.get(k) for k in ("chi2", "dof", "p", "misfit",
                                                          "model_form_sd")},
                   "parameters": {}}
            for p, true in truth["R"].items():
                if p not in ident.posterior.names:
                    continue
                lo, hi = ident.posterior.interval(p)
                row["parameters"][p] = {
                    "truth": true, "best": ident.posterior.best[p], "interval_90": [lo, hi],
                    "best_nominal_inputs": ident.at_nominal.best[p],
                    "interval_90_nominal_inputs": list(ident.at_nominal.interval(p)),
                    "covered": bool(lo <= true <= hi), "flag": parameter_flag(ident, p)}
            _write(out, row)
            print(f"{name} seed {seed}: " + "; ".join(
                f"{p} {d['best']:.3g} [{d['interval_90'][0]:.3g}, {d['interval_90'][1]:.3g}] "
                f"{'covered' if d['covered'] else 'MISSED'} ({d['flag']})"
                for p, d in row["parameters"].items()) + f" ({row['seconds']:.0f} s)",
                flush=True)
        report()


def summary() -> dict:
    """Per truth and resistance: seeds, coverage, misses flagged ``determined`` and whether
    the truth passes acceptance 2."""
    out: dict = {}
    for tf in sorted(RUNS.glob("*__truth.json")):
        truth = json.loads(tf.read_text())
        slug = tf.name[: -len("__truth.json")]
        rows = [json.loads(p.read_text()) for p in sorted(RUNS.glob(f"{slug}__seed*.json"))]
        if not rows:
            continue
        name = rows[0]["truth"]
        per: dict = {}
        for p, true in truth["R"].items():
            got = [r for r in rows if p in r["parameters"]]
            if not got:
                continue
            d = [r["parameters"][p] for r in got]
            covered = sum(x["covered"] for x in d)
            wrong = sum((not x["covered"]) and x["flag"] == "determined" for x in d)
            nominal = sum(x["interval_90_nominal_inputs"][0] <= true
                          <= x["interval_90_nominal_inputs"][1] for x in d)
            per[p] = {"truth": true, "seeds": len(d), "covered": covered,
                      "covered_nominal_inputs": nominal,
                      "missed_flagged_determined": wrong,
                      "flags": sorted({x["flag"] for x in d}),
                      "best_geomean": math.exp(float(np.mean([math.log(x["best"]) for x in d]))),
                      # issue 59: covered, no miss flagged determined, the point unbiased
                      "passes": (wrong == 0 and covered >= 0.8 * len(d) and BEST_RANGE[0]
                                 <= math.exp(float(np.mean([math.log(x["best"] / true)
                                                            for x in d]))) <= BEST_RANGE[1]),
                      "rows": [{"seed": r["seed"], **r["parameters"][p],
                                "chi2": r["fit"]["chi2"], "dof": r["fit"]["dof"]} for r in got]}
        out[name] = {"what": truth["what"], "k": truth["k"], "parameters": per}
    return out


def report() -> None:
    s = summary()
    lines = ["# Recovery against truths that do not share the model (issues 47, 59)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "", "See the study's docstring "
             "(`validation/input_recovery_study.py`) for how each truth was built.", ""]
    lines += ["| truth | what | resistance | truth (m^2 K/W) | seeds | covered (marginal) | "
              "covered at nominal inputs | missed and flagged determined | flags | "
              "best (geometric mean) | acceptance 2 |", "|---" * 11 + "|"]
    for name, t in s.items():
        for p, d in t["parameters"].items():
            lines.append(f"| {name} | {t['what']} | {p} | {d['truth']:.3g} | {d['seeds']} | "
                         f"{d['covered']} | {d['covered_nominal_inputs']} | "
                         f"{d['missed_flagged_determined']} | {', '.join(d['flags'])} | "
                         f"{d['best_geomean']:.3g} ({d['best_geomean'] / d['truth']:.2f} x) | "
                         f"{'holds' if d['passes'] else 'MISSES'} |")
    lines += ["", "Acceptance 2 (issue 59, fixed before the run) holds for a truth where no "
              "seed has the truth outside a value flagged determined, at least 8 of 10 seeds "
              f"cover it and the geometric mean of best / truth lies within {BEST_RANGE[0]}-"
              f"{BEST_RANGE[1]}. The identification is the joint posterior "
              "(`itr_identify.inference.joint`); the best value is the posterior median of "
              "ln R, read with the interval from the resistance's Rao-Blackwell marginal; the "
              "chi-square column is the fit's test with the inputs free within their priors "
              "(`itr_identify.inference.free_inputs_fit`). The issue-47 run of the earlier "
              "machinery is `input_recovery.md`.", ""]
    for name, t in s.items():
        lines += [f"## {name}", "", t["what"] + ".", "",
                  "| formulation | truth k_iso (W/mK) |", "|---|---|"]
        lines += [f"| {f} | {k:.4f} |" for f, k in t["k"].items()]
        for p, d in t["parameters"].items():
            lines += ["", f"{p} (truth {d['truth']:g}):", "",
                      "| noise seed | best | 90 % interval (marginal) | at nominal inputs | "
                      "covers | flag | chi-square / dof |", "|---|---|---|---|---|---|---|"]
            for r in d["rows"]:
                lo, hi = r["interval_90"]
                a, b = r["interval_90_nominal_inputs"]
                lines.append(f"| {r['seed']} | {r['best']:.3g} | {lo:.3g} - {hi:.3g} | "
                             f"{a:.3g} - {b:.3g} | {'yes' if r['covered'] else 'no'} | "
                             f"{r['flag']} | {r['chi2']:.1f} / {r['dof']} |")
        lines.append("")
    OUT.write_text("\n".join(lines) + "\n")
    OUT_JSON.write_text(json.dumps(s, indent=1))
    print(f"wrote {OUT}", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--truth", nargs="+", default=None, help="run only these truths")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args()
    if not args.report_only:
        run(args.seeds, args.truth)
    report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
