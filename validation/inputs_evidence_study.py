"""The two stated inputs against Table 3 with a faithful model (issue 39, item 4): Table 1 read
as number- or volume-weighted, and the silicone film at contacts (0 or 5 nm).

Table 3's Al2O3 formulations are identified (gap parametrisation) under each reading with a
model corrected to a converged box: the default (number-weighted, no film) with the shipped
corrections (32 um box), the other readings, which the shipped corrections do not hold, with
runtime corrections on the ``standard`` level's 24 um packings at 0.2 / 0.25 um (Al2O3-60 is
within 0.06 % of a 32 um box at 24 um, ``validation/results/box_size.md``). AlN is left out:
the shipped corrections hold the default reading only, and the runtime level's 24 um box is
not converged for AlN (``validation/results/box_convergence.md``), so a faithful AlN model
under the other readings needs its own 64 um campaigns (not run: device time). Each
reading's BIC and identified R_Al2O3_silicone go to
``validation/results/inputs_evidence.md``; each case's result is kept in
``validation/results/inputs_evidence_runs/`` as it finishes (a killed run redoes only the
unfinished cases).

Usage::

    python validation/inputs_evidence_study.py
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "validation" / "results"
RUNS = RESULTS / "inputs_evidence_runs"
CASES = {"number-weighted, no film (default)": {},
         "volume-weighted, no film": {"psd_basis": "volume"},
         "number-weighted, 5 nm film": {"min_gap_um": 0.005}}


def run() -> None:
    from itr_identify.forward.fidelity import faithful_for
    from itr_identify.inference.measurements import Measurements, read_measurements
    from itr_identify.inference.pipeline import identify
    from itr_identify.workflows.reproduce import ReproduceSettings

    RUNS.mkdir(parents=True, exist_ok=True)
    t3 = read_measurements()
    sub = Measurements({f: t3.values[f] for f in t3.formulations
                        if f.startswith("Al2O3-") and "AlN" not in f}, "Table 3, Al2O3")
    base = ReproduceSettings()
    for i, (name, change) in enumerate(CASES.items()):
        out = RUNS / f"case{i}.json"
        if out.exists():
            continue
        fwd = base.forward.with_(**change)
        if change:   # the shipped corrections hold the default reading only
            fwd = fwd.with_(faithful=faithful_for("standard"))
        t = time.perf_counter()
        ident = identify(sub, "gap", settings=fwd, grid_points=base.grid_points, seed=0,
                         echo=lambda line: print(line, flush=True))
        lo, hi = ident.posterior.interval("R_Al2O3_silicone")
        row = {"case": name, "settings": change, "fidelity": fwd.faithful.name,
               "bic": ident.bic(), "best": ident.posterior.best["R_Al2O3_silicone"],
               "interval_90": [lo, hi],
               "seconds": time.perf_counter() - t}
        tmp = out.with_suffix(".tmp")
        tmp.write_text(json.dumps(row, indent=1))
        tmp.replace(out)
        print(f"{name}: BIC {row['bic']:.2f}, R {row['best']:.3g} [{lo:.3g}, {hi:.3g}] "
              f"({row['seconds']:.0f} s)", flush=True)
        report()


def report() -> None:
    rows = [json.loads(p.read_text()) for p in sorted(RUNS.glob("case*.json"))]
    lines = ["# The stated inputs against Table 3 with a faithful model (issue 39)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| reading | correction | BIC | R_Al2O3_silicone (m^2 K/W) | 90 % interval | s |",
             "|---|---|---|---|---|---|"]
    ref = rows[0]["bic"] if rows else 0.0
    for r in rows:
        lo, hi = r["interval_90"]
        lines.append(f"| {r['case']} | {r['fidelity']} | {r['bic']:.2f} "
                     f"({r['bic'] - ref:+.2f}) | {r['best']:.3g} | {lo:.3g} - {hi:.3g} | "
                     f"{r['seconds']:.0f} |")
    if len(rows) == 3:
        d_vol, d_film = rows[1]["bic"] - ref, rows[2]["bic"] - ref
        lines += ["", f"- Basis: the volume-weighted reading's BIC is {d_vol:+.1f} against the "
                  "number-weighted one (2 to 6: positive evidence, 6 or more: strong). "
                  "Table 1's mean diameters are the means of its own lognormals, whichever the "
                  "weighting (``itr_fv/data/README.md``), so they do not decide; a laser "
                  "diffractometer's default output (volume) argues the other way. The data "
                  "favour the number reading, which stays the default; under the volume "
                  f"reading R_Al2O3_silicone reads {rows[1]['best'] / rows[0]['best']:.2f} "
                  "times the default's, and both values are reported here.",
                  f"- Film: a 5 nm film changes the BIC by {d_film:+.1f}: Table 3 cannot tell "
                  f"0 from 5 nm, while R_Al2O3_silicone moves by "
                  f"{rows[2]['best'] / rows[0]['best']:.2f} times. The film stays a stated "
                  "input (``--film-nm``, default 0: the packer's ~1 nm gaps), and every "
                  "error budget gives the 2 and 5 nm films' effect on each resistance."]
    (RESULTS / "inputs_evidence.md").write_text("\n".join(lines) + "\n")


def main() -> int:
    if "--report-only" not in sys.argv:
        run()
    report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
