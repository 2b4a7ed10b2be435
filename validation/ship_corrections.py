"""Ship the faithful corrections: assemble ``identify/data/corrections.json`` from the finished
campaigns of ``examples/corrections.toml`` and write its table
(``validation/results/shipped_corrections.md``).

The campaigns ran in ``validation/results/corrections_runs`` (issue 39): Al2O3 (32 um) and the
cheap replicas on the 2-core CPU (``solver = "mg"``), AlN's fine voxel (64 um at 0.2 um) on a
lent NVIDIA H200 (array-API FFT-PCG, portable kernels; its rows read back from the device log,
``validation/device_log_rows.py``) and AlN's coarse voxel (the same particles, 0.25 um) and
the hybrids (64 um at 0.25 um) on the CPU. ``itr corrections build examples/corrections.toml
--out DIR`` makes the same file from scratch on any workers.

Usage::

    python validation/ship_corrections.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "validation" / "results" / "corrections_runs"
OUT = ROOT / "identify" / "data" / "corrections.json"
REPORT = ROOT / "validation" / "results" / "shipped_corrections.md"
WHERE = {"Al2O3": "mg on the 2-core CPU (both voxels)",
         "AlN": "0.2 um: gpu on one NVIDIA H200 (array-API FFT-PCG, portable kernels; k_iso "
                "to 4 decimals from the device log); 0.25 um (the same particles): mg on the "
                "2-core CPU",
         "Al2O3-AlN": "mg on the 2-core CPU (0.25 um; voxel bias from Al2O3 and AlN)",
         "cheap": "fft on the 2-core CPU"}


def main() -> int:
    from itr_fv.io import write_text
    from itr_identify.forward.correction_plan import CorrectionPlan
    from itr_identify.forward.shipped import assemble

    plan = CorrectionPlan.from_toml(ROOT / "examples" / "corrections.toml")
    data = assemble(plan, RUNS, provenance={
        "solver": WHERE, "plan_file": "examples/corrections.toml",
        "runs": "validation/results/corrections_runs",
        "voxels_per_system_um": {s.name: list(plan.voxels_of(s.name)) for s in plan.systems}})
    write_text(OUT, json.dumps(data, indent=1) + "\n")
    print(f"wrote {OUT} ({len(data['points'])} points; systems {', '.join(data['systems'])})")
    prov = data["provenance"]
    lines = ["# The shipped faithful corrections (issue 39)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             f"Provenance: plan `{prov['plan']}`, commit {prov['commit'][:10]}, {prov['date']}; "
             f"boxes {prov['boxes_um']} um; voxels {prov['voxels_per_system_um']} um; packing "
             f"seeds {prov['seeds']}; tol {prov['tol']}; bias order {prov['bias_order']} +- "
             f"{prov['bias_order_se']}; cheap RVE {prov['cheap_rve']['box_um']:g} um at "
             f"{prov['cheap_rve']['voxel_um']:g} um, seeds {prov['cheap_rve']['seeds']}.", "",
             "c = k_faithful / k_cheap; k_faithful is the packings' mean with the voxel bias "
             "removed; the scatter is the relative standard error of that mean over the "
             "packings.", "",
             "| formulation | design point (m^2 K/W) | k_cheap | k_faithful per packing | c | "
             "packing scatter | voxel extrapolation | voxel bias removed |",
             "|---|---|---|---|---|---|---|---|"]
    for p in data["points"]:
        vals = ", ".join(f"{k} {v:.0e}" for k, v in p["values"].items())
        lines.append(f"| {p['formulation']} | {vals} | {p['k_cheap']:.4f} | "
                     + ", ".join(f"{k:.4f}" for k in p["k_faithful_iso"])
                     + f" | {p['c']:.4f} | {100 * p['packing_sd']:.2f} % | "
                     f"{100 * p['order_sd']:.2f} % | {100 * -p['voxel_bias']:+.2f} % |")
    lines += ["", "Fits c(phi, R) = a + b (phi - phi0) + sum_i d_i log10(R_i / R0):", "",
              "| system | box (um) | fractions | a | b | d | fit rms | largest residual | "
              "where solved |", "|---|---|---|---|---|---|---|---|---|"]
    for name, s in data["systems"].items():
        a, b, *d = s["coefficients"]
        lo, hi = s["fraction_range"]
        lines.append(f"| {name} | {s['box_um']:g} | {lo:.3f}-{hi:.3f} | {a:.4f} | {b:+.3f} | "
                     + ", ".join(f"{x:+.4f}" for x in d)
                     + f" | {100 * s['fit_rms']:.2f} % | {100 * s['max_residual']:.2f} % | "
                     f"{WHERE.get(name, '')} |")
    write_text(REPORT, "\n".join(lines) + "\n")
    print(f"wrote {REPORT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
