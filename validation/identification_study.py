"""Synthetic recovery of known interface resistances (issue 12, acceptance 1).

Known parameters (the paper's Table 5 values) -> every formulation of Table 2 solved with
the full solver (itr_fft, three directions) on three RVEs the forward models never saw,
averaged (packing seeds from 40 + 7 s for seed s: each seed a new set of samples, larger
than one RVE) -> four replicates per formulation with Gaussian noise at the paper's
replicate spread (Table 3 sample standard deviation) -> ``identify.pipeline.identify`` on
the noisy table, for 10 noise seeds and both parametrisations. Counted: the known value
inside the reported 90 % credible interval. The single-filler forward models do not depend
on the data and are built once; the two-filler ones (they hold the single-filler best
values) are rebuilt per seed. Settings: those of ``itr reproduce`` (12 um box, 0.25 um).

Writes ``validation/results/identification.md`` and ``identification.json``.

Usage::

    python validation/identification_study.py [--seeds 10] [--parametrisations area,gap]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TRUE = {"gap": {"R_Al2O3_silicone": 2.2e-8, "R_AlN_silicone": 3.0e-8},
        "area": {"R_Al2O3_silicone": 2.2e-8, "R_AlN_silicone": 3.0e-8,
                 "Rff_Al2O3_Al2O3": 2.0e-7, "Rff_AlN_AlN": 1.0e-7, "Rff_Al2O3_AlN": 3.0e-7}}


def truth(par: str, settings, seed: int) -> dict[str, float]:
    from identify.forward import PARAMETRISATIONS, ForwardModel, full_solve
    from identify.pipeline import fractions_of
    from surrogate import paper_data

    out = {}
    for f in paper_data.formulations():
        m = ForwardModel(f, fractions_of(f), PARAMETRISATIONS[par],
                         settings.with_(seed=40 + 7 * seed))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mat = m.materials({p: v for p, v in TRUE[par].items()
                               if p in m.parametrisation.parameters(list(m.fractions))})
            ks = [full_solve(m.pack(r), mat, settings.solver_tol).mean() for r in range(3)]
        out[f] = float(np.mean(ks))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--parametrisations", default="area,gap")
    ap.add_argument("--out", default=str(ROOT / "validation" / "results" / "identification"))
    args = ap.parse_args()
    from identify.measurements import Measurements, read_measurements
    from identify.pipeline import identify
    from identify.reproduce import ReproduceSettings

    settings = ReproduceSettings().forward
    table3 = read_measurements()
    results = {}
    for par in args.parametrisations.split(","):
        t0 = time.perf_counter()
        reuse, runs, truths = None, [], []
        for seed in range(args.seeds):
            k_true = truth(par, settings, seed)
            truths.append(k_true)
            rng = np.random.default_rng(1000 + seed)
            meas = Measurements({f: k + math.sqrt(table3.variance(f)) * rng.standard_normal(4)
                                 for f, k in k_true.items()}, f"synthetic {par} seed {seed}")
            ident = identify(meas, par, settings=settings, seed=seed, reuse=reuse,
                             echo=lambda s: None)
            reuse = ident.models
            row = {"seed": seed, "chi_square": ident.chi_square(), "parameters": {}}
            for p, v in TRUE[par].items():
                lo, hi = ident.posterior.interval(p)
                row["parameters"][p] = {"true": v, "best": ident.posterior.best[p],
                                        "median": ident.posterior.median(p),
                                        "interval_90": [lo, hi], "inside": lo <= v <= hi}
            runs.append(row)
            print(par, seed, {p: (f"{r['interval_90'][0]:.2e}-{r['interval_90'][1]:.2e}",
                                  r["inside"]) for p, r in row["parameters"].items()},
                  flush=True)
        results[par] = {"truth_k_iso": truths, "runs": runs,
                        "seconds": time.perf_counter() - t0}
    out = Path(args.out)
    out.with_suffix(".json").write_text(json.dumps(results, indent=2) + "\n")
    lines = ["# Synthetic recovery of known interface resistances", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| parametrisation | parameter | true (m^2 K/W) | inside the 90 % interval "
             "(of seeds) | median of the medians | typical interval (median lo - hi) |",
             "|---|---|---|---|---|---|"]
    for par, res in results.items():
        for p, v in TRUE[par].items():
            rows = [r["parameters"][p] for r in res["runs"]]
            inside = sum(r["inside"] for r in rows)
            med = float(np.median([r["median"] for r in rows]))
            lo = float(np.median([r["interval_90"][0] for r in rows]))
            hi = float(np.median([r["interval_90"][1] for r in rows]))
            lines.append(f"| {par} | {p} | {v:.1e} | {inside} / {len(rows)} | {med:.2e} | "
                         f"{lo:.2e} - {hi:.2e} |")
        all_in = sum(all(q["inside"] for q in r["parameters"].values()) for r in res["runs"])
        lines.append(f"| {par} | all parameters at once | | {all_in} / {len(res['runs'])} "
                     "| | |")
    lines += ["", "Wall time: " + ", ".join(f"{p} {r['seconds']:.0f} s"
                                            for p, r in results.items()) + "."]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out.with_suffix('.md')}")


if __name__ == "__main__":
    sys.exit(main())
