"""Ship the faithful corrections: assemble ``identify/data/corrections.json`` from the committed
parts of ``examples/corrections.toml`` (corrections-v2, issue 58) and write its report
(``validation/results/shipped_corrections.md`` and ``.json``).

The parts lie in ``validation/results/corrections_v2``:

- ``cpu/<campaign>``: run on the 2-core CPU (``itr corrections build examples/corrections.toml
  --out validation/results/corrections_v2/cpu --solved-in .../device --solved-in
  .../issue47``; solver ``mg``, the cheap RVEs ``fft``);
- ``device/<campaign>``: run on one lent NVIDIA H200
  (``validation/faithful_solves_on_device.py``, queue ``corrections58``: the array-API
  FFT-PCG, fused kernels; its ``device_log.txt``);
- ``issue47/<campaign>``: issue 47's AlN box study and tail cut (H200), as stores
  (``validation/corrections_issue47_rows.py``).

The report holds per system the box study, the voxel order per design point and the tail
cut (the shared terms), the table's factors, the fits, the old table (corrections-v1, the
earlier contact geometry, ``validation/results/corrections_v1.json``) against the new one at
the old table's points, and the plan's estimated hours against the measured wall of what
ran on the CPU. ``--check`` assembles into memory and compares with the shipped file
(exit 1 where they differ beyond 1e-12), writing nothing.

Usage::

    python validation/ship_corrections.py [--check]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PARTS = ROOT / "validation" / "results" / "corrections_v2"
ROOTS = [PARTS / "cpu", PARTS / "device", PARTS / "issue47"]
PLAN = ROOT / "examples" / "corrections.toml"
OUT = ROOT / "identify" / "data" / "corrections.json"
REPORT = ROOT / "validation" / "results" / "shipped_corrections.md"
REPORT_JSON = ROOT / "validation" / "results" / "shipped_corrections.json"
OLD = ROOT / "validation" / "results" / "corrections_v1.json"
CPU_WORKERS = 2


def where_solved(plan) -> dict[str, str]:
    """Per campaign where its parts were solved (cpu, device, issue47; several: all)."""
    out = {}
    for _, camp in plan.campaigns():
        at = [r.name for r in ROOTS if (r / camp.name / "parts").is_dir()
              and any((r / camp.name / "parts").glob("*.parquet"))]
        out[camp.name] = "+".join(at) or "not solved"
    return out


def build(plan) -> dict:
    from itr_identify.forward.corrections_table import assemble

    where = where_solved(plan)
    rel = [str(r.relative_to(ROOT)) for r in ROOTS]
    return assemble(plan, ROOTS, provenance={
        "solver": {"cpu": "mg on the 2-core CPU (the cheap RVEs: fft)",
                   "device": "gpu on one NVIDIA H200 (array-API FFT-PCG, fused kernels)",
                   "issue47": "gpu on one NVIDIA H200 (issue 47: array-API FFT-PCG)",
                   "campaigns": where},
        "plan_file": "examples/corrections.toml", "runs": rel})


def _stable(data: dict) -> dict:
    """The content without what changes at every assembly (commit, date)."""
    prov = {k: v for k, v in data["provenance"].items() if k not in ("commit", "date")}
    return {**data, "provenance": prov}


def hours_table(plan) -> list[str]:
    """Per campaign the plan's estimate (2 local workers) and the measured wall of its CPU
    solves (the rows' wall over the workers; packing not included)."""
    from itr_identify.forward.corrections_table import plan_rows
    from itr_surrogate.runner import local_workers
    from itr_surrogate.workload import Workload, campaign_workload

    lines = ["| campaign | grid | solves | estimated on 2 cores (h) | measured, CPU (h) | "
             "measured, H200 (s) |", "|---|---|---|---|---|---|"]
    tot_est = tot_cpu = tot_est_cpu = 0.0
    for _, camp in plan.campaigns():
        grid = campaign_workload(camp).grids[0]
        est = Workload((grid,), camp.solver, local_workers(CPU_WORKERS)).seconds() / 3600
        cpu = [r for r in plan_rows([PARTS / "cpu"], camp.name)]
        dev = [r for r in plan_rows([PARTS / "device", PARTS / "issue47"], camp.name)]
        cpu_h = sum(r["wall_s"] for r in cpu) / CPU_WORKERS / 3600
        tot_est += est
        if cpu:
            tot_cpu += cpu_h
            tot_est_cpu += est * len(cpu) / camp.n_solves()
        lines.append(f"| {camp.name} | {grid.n}^3 | {camp.n_solves()} | {est:.2f} | "
                     + (f"{cpu_h:.2f} ({len(cpu)} solves)" if cpu else "-") + " | "
                     + (f"{sum(r['wall_s'] for r in dev):.0f} ({len(dev)} solves)" if dev
                        else "-") + " |")
    lines.append(f"| **total** | | | **{tot_est:.2f}** | **{tot_cpu:.2f}** (estimated for "
                 f"these solves: {tot_est_cpu:.2f}) | |")
    return lines


def studies_md(data: dict) -> list[str]:
    lines = []
    for name, s in data["systems"].items():
        sh = s["shared"]
        box = sh["box"]
        lines += [f"### {name}", "",
                  f"Box study ({box['formulation']}, {sh['box']['boxes'][0]['box_um']:g}-"
                  f"{sh['box']['boxes'][-1]['box_um']:g} um at {s['voxel_um']:g} um, packing "
                  f"seeds from {box['seed']}):", "",
                  "| box (um) | packings | k_iso per packing | mean | standard error |",
                  "|---|---|---|---|---|"]
        for b in box["boxes"]:
            lines.append(f"| {b['box_um']:g} | {len(b['k_iso'])} | "
                         + ", ".join(f"{k:.4f}" for k in b["k_iso"])
                         + f" | {b['mean']:.4f} | {100 * b['se'] / b['mean']:.2f} % |")
        lines += ["", "| step | change of the mean | 90 % interval (Welch) |", "|---|---|---|"]
        for st in box["steps"]:
            lo, hi = st["interval"]
            lines.append(f"| {st['from_um']:g} -> {st['to_um']:g} um | {100 * st['rel']:+.2f} % "
                         f"| {100 * lo:+.2f} to {100 * hi:+.2f} % |")
        lines += ["", f"Converged (within 0.5 % of every larger box): {box['converged_um']:g} um. "
                  f"Box factor (the converged boxes' packings over the table box's, "
                  f"{box['table_box_um']:g} um): **{box['factor']:.4f}** (sd "
                  f"{100 * box['sd']:.2f} %).", "",
                  f"Voxel order ({sh['voxel']['formulation']}, {sh['voxel']['box_um']:g} um, the "
                  f"same particles at {', '.join(f'{v:g}' for v in sh['voxel']['voxels_um'])} "
                  "um; law k = a_j (1 + beta h^p), 90 % intervals by the order's profile):", "",
                  "| resistances (m^2 K/W) | packings | order p (90 %) | bias of "
                  f"{s['voxel_um']:g} um (90 %) | fit rms | dof |", "|---|---|---|---|---|---|"]
        for q in sh["voxel"]["points"]:
            vals = ", ".join(f"{v:.0e}" for v in q["values"].values())
            lo, hi = q["order_interval"]
            blo, bhi = q["bias_interval"]
            end = "" if q["order_bounded"] else ", at an end of the range fitted, 1-8"
            lines.append(f"| {vals} | {len(q['packings'])} | {q['order']:.2f} ({lo:.2f}-"
                         f"{hi:.2f}{end}) | "
                         f"{100 * q['bias']:+.2f} % ({100 * blo:+.2f} to {100 * bhi:+.2f} %) | "
                         f"{100 * q['rms']:.3f} % | {q['dof']} |")
        tail = sh["tail"]
        lines += ["", f"Tail cut ({tail['formulation']}, {tail['box_um']:g} um, against the "
                  f"box study's packings at the table's cut {tail['reference_quantile']:g}):",
                  "", "| number quantile cut | packings | mean k_iso | change | standard error |",
                  "|---|---|---|---|---|"]
        for q in tail["quantiles"]:
            lines.append(f"| {q['quantile']:g} | {len(q['k_iso'])} | {q['mean']:.4f} | "
                         f"{100 * q['rel']:+.2f} % | {100 * q['se']:.2f} % |")
        lines += ["", f"Tail term (not applied): sd {100 * tail['sd']:.2f} %.", ""]
    return lines


def points_md(data: dict) -> list[str]:
    lines = ["| formulation | resistances (m^2 K/W) | k_cheap | k_table per packing | box | "
             "voxel bias | c | packing (own) | shared |", "|---|---|---|---|---|---|---|---|---|"]
    for p in data["points"]:
        vals = ", ".join(f"{v:.1e}" for v in p["values"].values())
        lines.append(f"| {p['formulation']} | {vals} | {p['k_cheap']:.4f} | "
                     + ", ".join(f"{k:.4f}" for k in p["k_table_iso"])
                     + f" | x{p['box_factor']:.4f} | {100 * p['voxel_bias']:+.2f} % | "
                     f"{p['c']:.4f} | {100 * p['packing_sd']:.2f} % | "
                     f"{100 * p['shared_sd']:.2f} % |")
    lines += ["", "Fits (see `identify/forward/corrections_table.py` for the terms):", "",
              "| system | fractions | coefficients | fit rms | largest residual | packing sd "
              "(one packing, pooled) | dof |", "|---|---|---|---|---|---|---|"]
    for name, s in data["systems"].items():
        lo, hi = s["fraction_range"]
        lines.append(f"| {name} | {lo:.3f}-{hi:.3f} | "
                     + ", ".join(f"{c:+.4f}" for c in s["coefficients"])
                     + f" | {100 * s['fit_rms']:.2f} % | {100 * s['max_residual']:.2f} % | "
                     f"{100 * s['packing_sd']:.2f} % | {s['packing_dof']} |")
    return lines


def old_vs_new(data: dict) -> list[str]:
    """The old table's factors against the new one's at the old table's points."""
    from itr_fv.materials.formulation_names import fractions_of  # noqa: F401 - package data
    from itr_identify.forward.shipped import ShippedCorrections

    new = ShippedCorrections(data)
    old = json.loads(OLD.read_text())
    lines = ["| formulation | resistances (m^2 K/W) | old c (v1) | new c (v2) | new / old | new "
             "own sd | new shared sd |", "|---|---|---|---|---|---|---|"]
    for p in old["points"]:
        f = new.for_fractions(p["fractions"])
        if f is None:
            continue
        cols = {k: np.array([v]) for k, v in p["values"].items()}
        parts = f.parts(cols, 1)
        c = float(parts["c"][0])
        own = float(math.hypot(parts["packing"][0], parts["interpolation"][0]))
        vals = ", ".join(f"{v:.0e}" for v in p["values"].values())
        lines.append(f"| {p['formulation']} | {vals} | {p['c']:.4f} | {c:.4f} | "
                     f"{c / p['c']:.4f} | {100 * own:.2f} % | "
                     f"{100 * float(parts['shared'][0]):.2f} % |")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="compare a fresh assembly with the shipped file; write nothing")
    args = ap.parse_args()
    from itr_fv.io import write_text
    from itr_identify.forward.correction_plan import CorrectionPlan

    plan = CorrectionPlan.from_toml(PLAN)
    data = build(plan)
    if args.check:
        shipped = json.loads(OUT.read_text())
        same = json.dumps(_stable(shipped), sort_keys=True) == json.dumps(
            _stable(json.loads(json.dumps(data))), sort_keys=True)
        print("the shipped table is what the committed parts give" if same else
              "the shipped table differs from what the committed parts give")
        return 0 if same else 1
    missing = data["provenance"]["not_assembled"]
    write_text(OUT, json.dumps(data, indent=1) + "\n")
    print(f"wrote {OUT} ({len(data['points'])} points; systems {', '.join(data['systems'])}"
          + (f"; not assembled: {missing}" if missing else "") + ")")
    prov = data["provenance"]
    lines = ["# The shipped faithful corrections (issue 58: corrections-v2)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             f"Provenance: plan `{prov['plan']}`, commit {prov['commit'][:10]}, {prov['date']}; "
             f"contacts: {prov['contacts']} ({1000 * prov['film_um']:g} nm); table boxes "
             f"{prov['boxes_um']} um at {prov['voxels_um']} um; packing seeds {prov['seeds']}; "
             f"tol {prov['tol']}; cheap RVE {prov['cheap_rve']['box_um']:g} um at "
             f"{prov['cheap_rve']['voxel_um']:g} um, seeds {prov['cheap_rve']['seeds']}.", "",
             "## The shared terms per system", ""]
    lines += studies_md(data)
    lines += ["## The table", "", "c = k_faithful / k_cheap; k_faithful = mean_j k_table x box "
              "factor / (1 + voxel bias). `packing (own)`: the relative standard error of the "
              "formulation's mean from the pooled packing variance; `shared`: the system's "
              "box, voxel and tail terms in quadrature (one term for all its formulations).", ""]
    lines += points_md(data)
    lines += ["", "## Old against new", "", "The corrections-v1 table (2026-11-26, the packer's "
              "clearance read as a film; 2 packings, 2 resistances, one voxel-bias order for "
              "all systems) against this one at its points:", ""]
    lines += old_vs_new(data)
    lines += ["", "## Hours: the plan against what ran", "",
              "`itr corrections build examples/corrections.toml --plan` estimates each campaign "
              "from the solver's measured seconds per voxel (an order of magnitude); measured: "
              "the CPU rows' solve wall over the 2 workers (packing not included) and the "
              "H200's solve seconds.", ""]
    lines += hours_table(plan)
    write_text(REPORT, "\n".join(lines) + "\n")
    write_text(REPORT_JSON, json.dumps({"systems": {
        n: {k: s[k] for k in ("shared", "coefficients", "fit_rms", "packing_sd",
                              "packing_dof")} for n, s in data["systems"].items()}},
        indent=1) + "\n")
    print(f"wrote {REPORT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
