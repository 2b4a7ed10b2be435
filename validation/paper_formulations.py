"""The paper's twelve formulations under the gap contact model (issue 9, acceptance 6).

Every formulation of Table 2 is packed (Table 1 size distributions, diameters cut at 0.45
box), voxelized and solved with itr_fft (tol 1e-6, three load cases) under the gap contact
model with the paper's particle-matrix resistances (Table 5: Al2O3-silicone 2.2e-8,
AlN-silicone 3.0e-8 m^2 K/W) and no contact parameter: a contact is two particle-matrix
interfaces and the true silicone film between the spheres (the paper's Eq. 6). k_Al2O3 =
30, k_AlN = 200, k_silicone = 0.18 W/(m K) (the paper's values, ``itr_fv.materials.paper_data``).
Box and voxel are the recommended ones of ``box_size.md`` and ``resolution.md``: 24 um
for Al2O3, 40 um for AlN and the hybrids, 0.16 um voxels; two packings (seeds 1, 2) per
formulation. The table sets k_iso (trace / 3) beside the measured mean of Table 3 and the
paper's own prediction of Table 6 (made with its per-area contact resistances). Rows are kept in
``paper_formulations.csv`` (a re-run skips the solved ones). Writes
``validation/results/paper_formulations.md``.

Usage::

    python validation/paper_formulations.py [--voxel 0.16] [--seeds 1,2] [--only Al2O3-55,...]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from csv_store import append_row, load_rows  # noqa: E402

BOX_UM = {"Al2O3": 24.0, "AlN": 40.0, "hybrid": 40.0}
FINDINGS = """## Findings

- No parameter was fitted here: the only interface values are the paper's particle-matrix
  resistances, and a contact is two of them plus the true silicone film. The paper's
  predictions (Table 6) come from resistances identified on these same measurements,
  including a per-area contact resistance per filler pair.
- **Al2O3**: within -4.2 ... +6.0 % of the measured means (mean 4.0 %, the paper's 6.3 %).
- **AlN 55-60 %**: +0.1 ... +4.1 %. **AlN-62 %: -14.8 %**: the measured mean jumps by 25 %
  from 60 to 62 vol% (1.89 -> 2.37 W/(m K)), the simulation by 6 %; the paper's value matches
  because its contact resistance was fitted on 58/60/62 %. A steep rise near the packing
  limit is what a contact network that stiffens with fraction (contact spots, a thinner
  film at higher fraction) or a fraction error of the samples would give: a question for
  the identification and discrepancy stages, not for the solver.
- **Hybrids**: +13.1, +10.6, +9.5 % at 29/30/31 % of each filler, -1.6 % at 32.5 %: the
  measured series rises 46 % over these 7 vol%, the simulation 27 %. The gap model lets an
  Al2O3-AlN contact conduct like a same-filler contact; the paper identified the largest of
  its resistances for it (3e-7 m^2 K/W). The data ask for an extra Al2O3-AlN contact
  resistance, or for an effect that grows with fraction.
- Known biases of the settings: the 0.16 um voxel reads about 1.4 % low (``resolution.md``),
  two packings differ by 0.1-2.2 %, and the 40 um box still replaces 15.6 % of the AlN volume
  by smaller particles (k_iso +1.0 % from a 32 to a 40 um box, ``box_size.md``)."""

FIELDS = ["formulation", "seed", "box_um", "voxel_um", "n", "particles", "k_xx", "k_yy",
          "k_zz", "k_iso", "iterations", "wall_s"]


def family(fractions: dict[str, float]) -> str:
    return "hybrid" if len(fractions) > 1 else next(iter(fractions))


def solve(name: str, fractions: dict, seed: int, voxel_um: float) -> dict:
    import numpy as np

    from itr_fv import Materials, homogenize
    from itr_fv.materials import paper_data
    from itr_fv.rve import FillerSpec, RVESpec, generate_rve

    psd = paper_data.psd_lognormal()
    table5 = paper_data.paper_resistances()
    box = BOX_UM[family(fractions)]
    specs = [FillerSpec(f, mu=psd[f][0], sigma=psd[f][1], volume_fraction=v)
             for f, v in fractions.items()]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the box cut of AlN is reported in box_size.md
        ms = generate_rve(RVESpec(box, voxel_um, max_diameter_box_ratio=0.45), specs, seed,
                          matrix="silicone")
    mat = Materials({p: paper_data.PAPER_CONDUCTIVITY[p] for p in ("silicone", *fractions)},
                    {(f, "silicone"): table5[(f, "silicone")] for f in fractions},
                    matrix="silicone", contact="gap")
    t = time.perf_counter()
    res = homogenize(ms, mat, solver="fft", tol=1e-6, store_fields=False)
    k = np.diag(res.k_eff)
    return dict(formulation=name, seed=seed, box_um=box, voxel_um=voxel_um, n=ms.shape[0],
                particles=ms.n_particles, k_xx=f"{k[0]:.6f}", k_yy=f"{k[1]:.6f}",
                k_zz=f"{k[2]:.6f}", k_iso=f"{k.mean():.6f}", iterations=max(res.iterations),
                wall_s=f"{time.perf_counter() - t:.1f}")


def report(rows: list[dict], voxel_um: float, out: Path) -> None:
    from itr_fv.materials import paper_data
    from itr_identify.inference.measurements import read_measurements

    table3 = read_measurements()
    table6 = paper_data.paper_validation()
    forms = paper_data.formulations()
    lines = ["# The paper's formulations under the gap contact model", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| formulation | box (um) | n | k_iso seed 1 | k_iso seed 2 | mean (W/mK) | "
             "measured mean (Table 3) | ours vs measured (%) | paper's prediction (Table 6) | "
             "paper vs measured (%) | iterations | wall per solve (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    errs, paper_errs = {}, {}
    for name in forms:
        mine = sorted((r for r in rows if r["formulation"] == name and
                       float(r["voxel_um"]) == voxel_um), key=lambda r: int(r["seed"]))
        if not mine:
            continue
        ks = [float(r["k_iso"]) for r in mine]
        mean = statistics.fmean(ks)
        meas = table3.mean(name)
        pred = table6[name][1]
        errs[name] = 100 * (mean / meas - 1)
        paper_errs[name] = 100 * (pred / meas - 1)
        per_seed = [f"{k:.3f}" for k in ks] + [""] * (2 - len(ks))
        lines.append(f"| {name} | {mine[0]['box_um']} | {mine[0]['n']} | {per_seed[0]} | "
                     f"{per_seed[1]} | {mean:.3f} | {meas:.3f} | {errs[name]:+.1f} | "
                     f"{pred:.2f} | {paper_errs[name]:+.1f} | "
                     f"{'/'.join(r['iterations'] for r in mine)} | "
                     f"{'/'.join(r['wall_s'] for r in mine)} |")
    lines += ["", "Mean |relative error| against the measured means, per filler system:", ""]
    for fam in ("Al2O3", "AlN", "hybrid"):
        names = [n for n in errs if family(forms[n]) == fam]
        if names:
            lines.append(
                f"- {fam}: ours {statistics.fmean(abs(errs[n]) for n in names):.1f} % "
                f"(range {min(errs[n] for n in names):+.1f} to {max(errs[n] for n in names):+.1f}"
                f" %), the paper's {statistics.fmean(abs(paper_errs[n]) for n in names):.1f} %")
    out.write_text("\n".join(lines + ["", FINDINGS]) + "\n")
    print(f"wrote {out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxel", type=float, default=0.16, help="voxel edge, um")
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--only", default="", help="comma-separated formulations (default all)")
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "validation" / "results"
                                         / "paper_formulations.md"))
    args = ap.parse_args()
    from itr_fv.materials import paper_data

    store = Path(args.out).with_suffix(".csv")
    forms = paper_data.formulations()
    chosen = [n for n in forms if not args.only or n in args.only.split(",")]
    if not args.report_only:
        for name in chosen:
            for seed in (int(s) for s in args.seeds.split(",")):
                done = {(r["formulation"], int(r["seed"]), float(r["voxel_um"]))
                        for r in load_rows(store)}
                if (name, seed, args.voxel) in done:
                    continue
                row = solve(name, forms[name], seed, args.voxel)
                append_row(store, FIELDS, row)
                print(row, flush=True)
    report(load_rows(store), args.voxel, Path(args.out))


if __name__ == "__main__":
    sys.exit(main())
